"""pytorch-es's fitness shaping: the NES utilities of Wierstra et al. (2014), as pytorch-es computed them.

atgambardella/pytorch-es ``train.py`` (``fitness_shaping``, docs/original.md, "pytorch-es"), with the log-base fix
of its PR #8 (60bffea): with lambda members and rank k (1 = best),

    u_k = max(0, log2(lambda/2 + 1) - log2 k) / sum_m max(0, log2(lambda/2 + 1) - log2 k_m) + 1/lambda

- ranks come from the returns sorted in descending order, a tied value taking the *first* (best)
  rank of its run (``list.index``), so tied members get equal utilities;
- the denominator sums the numerators of the members' own ranks, which is
  sum_{j=1..lambda} max(0, log2(lambda/2 + 1) - log2 j) when there are no ties;
- Wierstra et al. subtract 1/lambda; pytorch-es adds it. With mirrored pairs the constant cancels
  in the step (u_+ eps - u_- eps), so it does not move theta.

Only the better half (k <= lambda/2) gets more than 1/lambda. ``nes_utilities`` has the signature of
``es.shaping.Shaping``: it returns None when every fitness is equal (no direction to step in).
"""

from __future__ import annotations

import numpy as np

from es import exact


def nes_utilities(fitness: np.ndarray) -> np.ndarray | None:
    """pytorch-es's utility of each member, in member order; None when all fitness values are equal."""
    fitness = np.asarray(fitness, dtype=np.float64)
    population = fitness.size
    if population == 0 or np.all(fitness == fitness[0]):
        return None
    ranks = 1 + population - np.searchsorted(np.sort(fitness), fitness, side="right")  # 1 + how many are better
    numerators = np.maximum(0.0, exact.log2(population / 2 + 1) - exact.log2(ranks))
    return numerators / numerators.sum() + 1.0 / population
