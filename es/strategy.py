"""The evolution strategy of the original code: OpenAI-ES with mirrored sampling and plain SGD.

Salimans et al. 2017 ("Evolution Strategies as a Scalable Alternative to Reinforcement Learning"),
Algorithm 2, as adapted by Najarro & Risi 2020 (upstream spec §2):

- mirrored sampling: members 2p and 2p+1 are theta + sigma*eps_p and theta - sigma*eps_p;
- fitness shaping: centered ranks in [-0.5, 0.5], then standardised;
- step: theta += lr / (N * sigma) * sum_m F_m * eps_m, N the population size;
- schedules: lr *= decay while lr > 0.001; sigma *= 0.999 while sigma > 0.01.

The perturbations eps_p are slices of a shared noise table (``es.noise``), so a member is only a
noise index and a sign. ``ask``/``tell`` work on a flat float32 vector and never print; ``tell``
returns the new state and a dict of metrics.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from es.noise import NoiseTable

LR_FLOOR = 0.001
SIGMA_DECAY = 0.999
SIGMA_FLOOR = 0.01


def centered_ranks(fitness: np.ndarray) -> np.ndarray:
    """Ranks scaled to [-0.5, 0.5]; tied values share their average rank.

    The original broke ties by sort position, which, for a mirrored pair with equal returns,
    always ranked the same sign higher and so stepped along -eps for no reason. With averaged
    ranks a tied pair cancels exactly. Without ties the result is the original's.
    """
    fitness = np.asarray(fitness, dtype=np.float64)
    n = fitness.size
    order = np.argsort(fitness, kind="stable")
    sorted_values = fitness[order]
    ranks = np.empty(n, dtype=np.float64)
    start = 0
    while start < n:  # walk runs of equal values
        stop = start + 1
        while stop < n and sorted_values[stop] == sorted_values[start]:
            stop += 1
        ranks[order[start:stop]] = (start + stop - 1) / 2.0
        start = stop
    return ranks / (n - 1) - 0.5


def standardise(values: np.ndarray) -> np.ndarray | None:
    """(values - mean) / std, or None when every value is the same (no direction to step in)."""
    std = values.std()
    if std == 0:
        return None
    return (values - values.mean()) / std


def shape_fitness(fitness: np.ndarray) -> np.ndarray | None:
    return standardise(centered_ranks(fitness))


def decay_lr(lr: float, decay: float) -> float:
    return lr * decay if lr > LR_FLOOR else lr


def decay_sigma(sigma: float) -> float:
    return sigma * SIGMA_DECAY if sigma > SIGMA_FLOOR else sigma


@dataclass(frozen=True)
class ESState:
    theta: np.ndarray  # float32
    lr: float
    sigma: float
    generation: int = 0  # generations done


@dataclass(frozen=True)
class OpenES:
    population_size: int  # even: mirrored pairs
    decay: float

    def __post_init__(self) -> None:
        if self.population_size < 2 or self.population_size % 2:
            raise ValueError(f"population size must be even and >= 2, got {self.population_size}")

    @property
    def pairs(self) -> int:
        return self.population_size // 2

    def ask(self, rng: np.random.Generator, noise: NoiseTable, dim: int) -> tuple[np.ndarray, np.ndarray]:
        """Noise index and sign of every member, in member order [+e1, -e1, +e2, -e2, ...]."""
        indices = noise.sample_indices(rng, dim, self.pairs)
        return np.repeat(indices, 2), np.tile(np.array([1, -1], dtype=np.int8), self.pairs)

    def tell(self, state: ESState, noise: NoiseTable, indices: np.ndarray,
             fitness: np.ndarray) -> tuple[ESState, dict]:
        """One SGD step from the fitness of each member (member order, higher is better)."""
        if fitness.shape != (self.population_size,):
            raise ValueError(f"expected {self.population_size} fitness values, got shape {fitness.shape}")
        shaped = shape_fitness(fitness)
        update_factor = state.lr / (self.population_size * state.sigma)
        theta = state.theta
        if shaped is not None:
            dim = theta.size
            pair_weights = shaped[0::2] - shaped[1::2]  # F+ eps + F- (-eps) = (F+ - F-) eps
            gradient = np.zeros(dim, dtype=np.float64)
            for weight, index in zip(pair_weights, indices[0::2]):
                gradient += weight * noise.slice(index, dim)
            theta = (theta + update_factor * gradient).astype(np.float32)
        new_state = replace(state, theta=theta, lr=decay_lr(state.lr, self.decay),
                            sigma=decay_sigma(state.sigma), generation=state.generation + 1)
        return new_state, {"update_factor": update_factor, "skipped": shaped is None}
