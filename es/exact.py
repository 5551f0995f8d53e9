"""Element-wise exp and logarithms, and the Euclidean norm, whose bits do not depend on the CPU.

numpy's float64 ``exp``, ``log`` and ``log2`` run a loop of numpy's own where the CPU has AVX-512 and
the C library's functions elsewhere, and the two differ in the last bit of some results;
``numpy.linalg.norm`` sums through BLAS, whose kernel, and so the order of its sum, depends on the CPU.
The strategies' updates use these instead: the C library's functions called one value at a time (the
``math`` module), and sums in numpy's pairwise order, which numpy's code fixes whatever the CPU.
"""

from __future__ import annotations

import math

import numpy as np


def _each(function, values) -> np.ndarray:
    values = np.asarray(values, dtype=np.float64)
    flat = np.fromiter(map(function, values.reshape(-1).tolist()), dtype=np.float64, count=values.size)
    return flat.reshape(values.shape)


def exp(values) -> np.ndarray:
    return _each(math.exp, values)


def log(values) -> np.ndarray:
    return _each(math.log, values)


def log2(values) -> np.ndarray:
    return _each(math.log2, values)


def norm(values: np.ndarray) -> float:
    """sqrt(sum of squares), the sum pairwise in float64."""
    return math.sqrt(float(np.sum(np.square(values, dtype=np.float64))))
