"""The ask/tell interface every strategy shares, and what a strategy declares as a plug-in.

The interface (``Strategy``, in the style of evosax): ``initial_state(theta)``; ``ask(state, rng,
noise)`` returns the generation's ``Population`` -- a noise index and a sign per member (the wire
protocol of docs/how-it-works.md), and what the workers need beside theta: a per-parameter sigma (``scale``)
or, for a strategy that cannot draw from the noise table, the members' vectors (``rows``), both
published once per generation as theta is; ``tell(state, noise, population, fitness)`` returns the
new ``ESState`` and a dict of metrics (``update_factor``, ``skipped``). A strategy's own arrays live
in ``ESState.strategy`` and the optimiser's in ``ESState.optimizer``, both saved in the checkpoint.

A strategy's module (``es.strategies``) declares, as evosax's algorithms own their parameters, its plug-in
(``StrategyPlugin``, ``plugins``): its name; its settings, a frozen dataclass of its own fields made with
``settings.setting()`` (each then has an effect only with ``--strategy`` naming it, and config.json records it
only then: ``es.settings.ESSettings`` joins them to the search's, which every strategy reads: ``popsize``,
``sigma``); the factory from the run's settings and the number of parameters; and its population rule,
``pairs``, with no default: whether its members are mirrored pairs, which needs an even ``--popsize``
(refused in one line otherwise, never rounded). Whether a generation's members share their episode seeds is
what its population is (``Population.mirrored``), never a flag a strategy could forget to set.

The registry of strategies is ``es.strategies.STRATEGIES``, one line per strategy.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from es.noise import NoiseTable
from es.optimizers import OptimizerState
from plugins import Plugin

STRATEGY_GROUP = "strategies beyond the original's OpenAI-ES (--strategy openai)"  # their flags' --help group


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
    scale: np.ndarray | None = None  # float32 (dim,): per-parameter sigma, published with theta
    rows: np.ndarray | None = None  # float32 (members, dim): the members themselves, published with theta

    @property
    def mirrored(self) -> bool:
        """Members 2p and 2p+1 are a mirrored pair, theta +- the same slice: they share their episode seeds
        (common random numbers). What the members are says it; no strategy declares it."""
        signs, indices = self.signs, self.indices
        return (self.rows is None and signs.size % 2 == 0 and bool((signs[0::2] == 1).all())
                and bool((signs[1::2] == -1).all()) and bool((indices[0::2] == indices[1::2]).all()))


class Strategy(Protocol):
    population_size: int

    def initial_state(self, theta: np.ndarray) -> ESState:
        """The state before the first generation, centred on ``theta``."""

    def ask(self, state: ESState, rng: np.random.Generator, noise: NoiseTable) -> Population:
        """The generation's members; every random draw comes from ``rng``."""

    def tell(self, state: ESState, noise: NoiseTable, population: Population,
             fitness: np.ndarray) -> tuple[ESState, dict]:
        """The next state from each member's fitness (member order, higher is better), and metrics."""


@dataclass(frozen=True, kw_only=True)
class StrategyPlugin(Plugin):
    """A strategy as its module declares it (``plugins.Plugin``: its name, what it is, its settings)."""

    make: Callable[[Any, int], Strategy]  # (the run's ``es.settings.ESSettings``, the number of parameters) -> it
    pairs: bool  # its members are mirrored pairs: --popsize must be even
    validate: Callable[[Any], None] | None = None  # what its settings refuse beyond each one's range (a ValueError)

    def check(self, settings) -> None:
        """The population rule, then the strategy's own (``validate``): a ValueError in one line."""
        size = settings.popsize
        if self.pairs and size % 2:
            raise ValueError(f"--popsize {size} is odd, but --strategy {self.name} samples mirrored pairs; give an "
                             f"even --popsize such as {size - 1} or {size + 1}")
        if self.validate is not None:
            self.validate(settings)


def mirrored_population(rng: np.random.Generator, noise: NoiseTable, dim: int, pairs: int) -> Population:
    """``pairs`` noise slices, each taken with + then - : [+e1, -e1, +e2, -e2, ...]."""
    indices = noise.sample_indices(rng, dim, pairs)
    return Population(np.repeat(indices, 2), np.tile(np.array([1, -1], dtype=np.int8), pairs))


def check_fitness(fitness: np.ndarray, population_size: int) -> None:
    if fitness.shape != (population_size,):
        raise ValueError(f"expected {population_size} fitness values, got shape {fitness.shape}")
