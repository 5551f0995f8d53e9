"""Fitness: the original's L2 penalty, and fitness shaping (rank transforms) before the step.

Najarro & Risi (2020), as the OpenAI-ES of Salimans et al. (2017) they adapt (docs/original.md, "The
evolution strategy"):
the fitness of member m is its episode return minus ``fitness_l2 * mean(theta_m^2)`` over the
penalised part of its parameters (all static weights; the Hebbian coefficients only), and the step
uses centered ranks in [-0.5, 0.5], then standardised ("rank_std").

``SHAPINGS`` is the one registry of shapings (``--shaping``):

    rank_std  the original: centered ranks, then standardised (x 3.447 at N = 200; docs/original.md, "The
              evolution strategy")
    rank      OpenAI es-starter's ``centered_rank`` (the same page): the centered ranks alone
    none      the fitness itself, standardised (non-finite fitness counts as the lowest finite one)
    nes       pytorch-es's NES utilities (Wierstra et al. 2014; docs/original.md, "pytorch-es"; the log-base fix
              included), ``es.nes``

Each returns None when every member is equal: there is no direction to step in.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from es.nes import nes_utilities

Shaping = Callable[[np.ndarray], "np.ndarray | None"]  # None: no direction to step in


def l2_penalty(params: np.ndarray) -> float:
    """mean(params^2), in float64: the penalty term of one member's fitness."""
    return float(np.mean(np.square(params, dtype=np.float64)))


def penalised_fitness(returns: np.ndarray, penalties: np.ndarray, coefficient: float) -> np.ndarray:
    """Return minus the L2 term; NaN or infinite results become -inf, ranked last and never stepped on."""
    fitness = returns - coefficient * penalties
    fitness[~np.isfinite(fitness)] = -np.inf
    return fitness


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


def rank_std(fitness: np.ndarray) -> np.ndarray | None:
    """The original's shaping: centered ranks, then standardised."""
    return standardise(centered_ranks(fitness))


def rank(fitness: np.ndarray) -> np.ndarray | None:
    """OpenAI's centered ranks in [-0.5, 0.5], without the original's standardisation."""
    ranks = centered_ranks(fitness)
    return ranks if ranks.any() else None


def standardised_fitness(fitness: np.ndarray) -> np.ndarray | None:
    """Raw fitness, standardised. NaN and infinite values (ranked last by the other shapings) take the
    lowest finite value, so that they never reach theta; if none is finite there is nothing to step on."""
    fitness = np.asarray(fitness, dtype=np.float64)
    finite = np.isfinite(fitness)
    if not finite.any():
        return None
    return standardise(np.where(finite, fitness, fitness[finite].min()))


SHAPINGS: dict[str, Shaping] = {"rank_std": rank_std, "rank": rank, "none": standardised_fitness,
                                 "nes": nes_utilities}
