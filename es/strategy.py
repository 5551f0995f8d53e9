"""The ask/tell interface every strategy shares, and the strategy of the original code: OpenAI-ES.

The interface (``Strategy``, in the style of evosax): ``initial_state(theta)``; ``ask(state, rng,
noise)`` returns the generation's ``Population`` -- a noise index and a sign per member (the wire
protocol of docs/how-it-works.md), and what the workers need beside theta: a per-parameter sigma (``scale``)
or, for a strategy that cannot draw from the noise table, the members' vectors (``rows``), both
published once per generation as theta is; ``tell(state, noise, population, fitness)`` returns the
new ``ESState`` and a dict of metrics (``update_factor``, ``skipped``). A strategy's own arrays live
in ``ESState.strategy`` and the optimiser's in ``ESState.optimizer``, both saved in the checkpoint.
The registry of strategies is ``es.strategies.STRATEGIES``.

OpenAI-ES with mirrored sampling:

Salimans et al. 2017 ("Evolution Strategies as a Scalable Alternative to Reinforcement Learning"),
Algorithm 2, as adapted by Najarro & Risi 2020 (docs/original.md, "The evolution strategy"):

- mirrored sampling: members 2p and 2p+1 are theta + sigma*eps_p and theta - sigma*eps_p;
- fitness shaping (``es.shaping``), injected: by default centered ranks, then standardised;
- the step (``es.optimizers``), injected: by default theta += lr / (N * sigma) * sum_m F_m * eps_m;
  OpenAI's Adam or momentum on request, each with optional weight decay in the gradient;
- schedules: lr *= decay while lr > lr_floor; sigma *= sigma_decay while sigma > sigma_floor,
  whatever the optimiser (lr is its step size).

``OpenES(settings)`` picks the shaping and the optimiser the settings name (``--shaping``,
``--optimizer``) from their registries.

The perturbations eps_p are slices of a shared noise table (``es.noise``), so a member is only a
noise index and a sign. ``ask``/``tell`` work on a flat float32 vector and never print; ``tell``
returns the new state and a dict of metrics.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np

from es.noise import NoiseTable
from es.optimizers import Optimizer, OptimizerState, make_optimizer
from es.shaping import SHAPINGS, Shaping


class ESSettings(Protocol):
    """What a strategy reads of its settings: ``es.settings.ESSettings``, which imports the strategy
    registry for its choices, so the strategies name it by this protocol instead of importing it."""

    def __getattr__(self, name: str) -> Any: ...


@dataclass(frozen=True)
class ESState:
    theta: np.ndarray  # float32: the centre, what the run saves and evaluates
    lr: float  # the step size (the metrics' lr column)
    sigma: float  # the search's scale (the metrics' sigma column; the mean of a per-parameter sigma)
    generation: int = 0  # generations done
    optimizer: OptimizerState = field(default_factory=dict)
    strategy: dict[str, np.ndarray] = field(default_factory=dict)  # the strategy's own arrays (PGPE's sigma, ...)


@dataclass(frozen=True)
class Population:
    """One generation's members as the workers rebuild them: member m is
    ``theta + signs[m] * sigma * noise[indices[m] : indices[m] + dim]``, with ``scale`` (a float32
    per-parameter sigma) in place of sigma where given, or ``rows[indices[m]]`` where rows are given."""

    indices: np.ndarray  # int64: noise index (or row of ``rows``) of each member
    signs: np.ndarray  # int8: +1 or -1
    mirrored: bool = True  # members 2p and 2p+1 are a mirrored pair: they share their episode seeds
    scale: np.ndarray | None = None  # float32 (dim,): per-parameter sigma, published with theta
    rows: np.ndarray | None = None  # float32 (members, dim): the members themselves, published with theta


class Strategy(Protocol):
    population_size: int

    def initial_state(self, theta: np.ndarray) -> ESState:
        """The state before the first generation, centred on ``theta``."""

    def ask(self, state: ESState, rng: np.random.Generator, noise: NoiseTable) -> Population:
        """The generation's members; every random draw comes from ``rng``."""

    def tell(self, state: ESState, noise: NoiseTable, population: Population,
             fitness: np.ndarray) -> tuple[ESState, dict]:
        """The next state from each member's fitness (member order, higher is better), and metrics."""


def mirrored_population(rng: np.random.Generator, noise: NoiseTable, dim: int, pairs: int) -> Population:
    """``pairs`` noise slices, each taken with + then - : [+e1, -e1, +e2, -e2, ...]."""
    indices = noise.sample_indices(rng, dim, pairs)
    return Population(np.repeat(indices, 2), np.tile(np.array([1, -1], dtype=np.int8), pairs))


def check_fitness(fitness: np.ndarray, population_size: int) -> None:
    if fitness.shape != (population_size,):
        raise ValueError(f"expected {population_size} fitness values, got shape {fitness.shape}")


def decay_lr(lr: float, settings: ESSettings) -> float:
    return lr * settings.decay if lr > settings.lr_floor else lr


def decay_sigma(sigma: float, settings: ESSettings) -> float:
    return sigma * settings.sigma_decay if sigma > settings.sigma_floor else sigma


@dataclass(frozen=True)
class OpenES:
    settings: ESSettings
    shaping: Shaping | None = None  # default: the one settings.shaping names
    optimizer: Optimizer | None = None  # default: the one settings.optimizer names

    def __post_init__(self) -> None:
        if self.shaping is None:
            object.__setattr__(self, "shaping", SHAPINGS[self.settings.shaping])
        if self.optimizer is None:
            object.__setattr__(self, "optimizer", make_optimizer(self.settings))
        size = self.settings.popsize
        if size < 2 or size % 2:
            raise ValueError(f"population size must be even and >= 2, got {size}")

    @property
    def population_size(self) -> int:
        return self.settings.popsize

    @property
    def pairs(self) -> int:
        return self.population_size // 2

    def initial_state(self, theta: np.ndarray) -> ESState:
        return ESState(np.asarray(theta, dtype=np.float32), self.settings.lr, self.settings.sigma)

    def ask(self, state: ESState, rng: np.random.Generator, noise: NoiseTable) -> Population:
        """Noise index and sign of every member, in member order [+e1, -e1, +e2, -e2, ...]."""
        return mirrored_population(rng, noise, state.theta.size, self.pairs)

    def tell(self, state: ESState, noise: NoiseTable, population: Population,
             fitness: np.ndarray) -> tuple[ESState, dict]:
        """One step from the fitness of each member (member order, higher is better)."""
        check_fitness(fitness, self.population_size)
        shaped = self.shaping(fitness)
        normaliser = self.population_size * state.sigma
        theta, optimizer_state = state.theta, state.optimizer
        if shaped is not None:
            weighted_sum = self.weighted_noise(shaped, population.indices, noise, theta.size)
            with np.errstate(over="ignore", invalid="ignore"):  # a non-finite step is the caller's to refuse
                theta, optimizer_state = self.optimizer.step(theta, weighted_sum, self.population_size, state.sigma,
                                                             state.lr, optimizer_state)
        new_state = replace(state, theta=theta, lr=decay_lr(state.lr, self.settings),
                            sigma=decay_sigma(state.sigma, self.settings), generation=state.generation + 1,
                            optimizer=optimizer_state)
        return new_state, {"update_factor": state.lr / normaliser, "skipped": shaped is None}

    @staticmethod
    def weighted_noise(shaped: np.ndarray, indices: np.ndarray, noise: NoiseTable, dim: int) -> np.ndarray:
        """sum_m F_m eps_m over mirrored pairs: F+ eps + F- (-eps) = (F+ - F-) eps, in float64."""
        total = np.zeros(dim, dtype=np.float64)
        for weight, index in zip(shaped[0::2] - shaped[1::2], indices[0::2]):
            total += weight * noise.slice(index, dim)
        return total
