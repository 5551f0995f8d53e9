"""The evolution strategy of the original code: OpenAI-ES with mirrored sampling, ask/tell.

Salimans et al. 2017 ("Evolution Strategies as a Scalable Alternative to Reinforcement Learning"),
Algorithm 2, as adapted by Najarro & Risi 2020 (upstream spec §2.1):

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

import numpy as np

from es.noise import NoiseTable
from es.optimizers import Optimizer, OptimizerState, make_optimizer
from es.settings import ESSettings
from es.shaping import SHAPINGS, Shaping


@dataclass(frozen=True)
class ESState:
    theta: np.ndarray  # float32
    lr: float
    sigma: float
    generation: int = 0  # generations done
    optimizer: OptimizerState = field(default_factory=dict)


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

    def ask(self, rng: np.random.Generator, noise: NoiseTable, dim: int) -> tuple[np.ndarray, np.ndarray]:
        """Noise index and sign of every member, in member order [+e1, -e1, +e2, -e2, ...]."""
        indices = noise.sample_indices(rng, dim, self.pairs)
        return np.repeat(indices, 2), np.tile(np.array([1, -1], dtype=np.int8), self.pairs)

    def tell(self, state: ESState, noise: NoiseTable, indices: np.ndarray,
             fitness: np.ndarray) -> tuple[ESState, dict]:
        """One step from the fitness of each member (member order, higher is better)."""
        if fitness.shape != (self.population_size,):
            raise ValueError(f"expected {self.population_size} fitness values, got shape {fitness.shape}")
        shaped = self.shaping(fitness)
        normaliser = self.population_size * state.sigma
        theta, optimizer_state = state.theta, state.optimizer
        if shaped is not None:
            weighted_sum = self.weighted_noise(shaped, indices, noise, theta.size)
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
