"""The elementary functions of the project's networks: tanh, exp and the logistic sigmoid in float32, each
a fixed sequence of IEEE 754 operations written here.

A call to the C library's ``tanhf`` or ``expf``, to numpy's vectorised loops or to torch's kernels gives
results that differ in the last bits between C libraries, instruction sets (numpy and torch pick an
AVX-512, AVX2 or plain loop at run time) and versions; a network's output, and so a run, would then
depend on the machine. These functions give the same bits on every machine (docs/reproducibility.md),
and their loops vectorise. Compiled without fastmath, so nothing is reordered or fused.

- ``rational_tanh``: the minimax rational form Eigen and XLA use for float32, clamped where tanh rounds
  to +-1 in float32: within 4.2e-7 of tanh (absolute) over all float32 inputs. In float32 ulps the error
  is largest just above float32's smallest normal, where ``x * p`` is subnormal before the division (about
  100 ulps there); ``benchmarks/cnn.py --tanh_every 1`` measures both over every float. It is not monotonic
  to the last bit. NaN stays NaN, -0 stays -0.
- ``exp32``: exp(x) = 2^n exp(r), n = round(x / ln 2), r = x - n ln 2 in two parts (Cody & Waite 1980),
  exp(r) by its Taylor polynomial of degree 7 (|r| <= 0.35: truncation below 1e-8, relative), 2^n from a
  table of exact powers of two. Within 1.2 ulp of exp where exp is a normal float32 (checked over 2 million
  points, ``tests/test_elementary.py``); subnormal below, 0 below -104, inf above 88.72; NaN for NaN.
- ``sigmoid32``: 1 / (1 + exp32(-x)).
"""

from __future__ import annotations

import numpy as np
from numba import njit

_FLAGS = dict(cache=True, nogil=True, error_model="numpy")  # numpy's: IEEE division, no Python zero check

_TANH_CLAMP = np.float32(7.90531110763549805)
_TANH_P = tuple(np.float32(c) for c in (-2.76076847742355e-16, 2.00018790482477e-13, -8.60467152213735e-11,
                                        5.12229709037114e-08, 1.48572235717979e-05, 6.37261928875436e-04,
                                        4.89352455891786e-03))
_TANH_Q = tuple(np.float32(c) for c in (1.19825839466702e-06, 1.18534705686654e-04, 2.26843463243900e-03,
                                        4.89352518554385e-03))
P0, P1, P2, P3, P4, P5, P6 = _TANH_P
Q0, Q1, Q2, Q3 = _TANH_Q


@njit(inline="always", **_FLAGS)
def rational_tanh(x: np.float32) -> np.float32:
    """tanh of a float32, as the rational form of the module's docstring evaluated as written."""
    x = _TANH_CLAMP if x > _TANH_CLAMP else x
    x = -_TANH_CLAMP if x < -_TANH_CLAMP else x
    x2 = x * x
    p = (((((P0 * x2 + P1) * x2 + P2) * x2 + P3) * x2 + P4) * x2 + P5) * x2 + P6
    q = ((Q0 * x2 + Q1) * x2 + Q2) * x2 + Q3
    return x * p / q


@njit(**_FLAGS)
def tanh_in_place(values: np.ndarray) -> None:
    """``rational_tanh`` of every value of a contiguous float32 array, in place."""
    flat = values.reshape(-1)
    for index in range(flat.size):
        flat[index] = rational_tanh(flat[index])


_EXP_LOW, _EXP_HIGH = -151, 127  # the powers of two exp32 takes (2^-150 and 2^-151 round to 0 in float32)
_POW2 = np.ldexp(1.0, np.arange(_EXP_LOW, _EXP_HIGH + 1)).astype(np.float32)  # exact, or 0
_LOG2E = np.float32(1.44269504088896341)
_LN2_HIGH = np.float32(0.693359375)  # ln 2 to 9 bits: n * _LN2_HIGH is exact for |n| < 2^15
_LN2_LOW = np.float32(-2.12194440e-4)  # ln 2 - _LN2_HIGH
_X_LOW, _X_HIGH = np.float32(-104.0), np.float32(89.0)  # exp32 is 0 below, inf above (float32's range)
_E = tuple(np.float32(1.0 / c) for c in (5040.0, 720.0, 120.0, 24.0, 6.0, 2.0, 1.0, 1.0))  # 1/7! ... 1/0!
E7, E6, E5, E4, E3, E2, E1, E0 = _E


@njit(inline="always", **_FLAGS)
def exp32(x: np.float32) -> np.float32:
    """exp of a float32, as the module's docstring says; NaN for NaN."""
    x = _X_LOW if x < _X_LOW else x
    x = _X_HIGH if x > _X_HIGH else x
    n = np.floor(x * _LOG2E + np.float32(0.5))
    r = (x - n * _LN2_HIGH) - n * _LN2_LOW
    p = ((((((E7 * r + E6) * r + E5) * r + E4) * r + E3) * r + E2) * r + E1) * r + E0
    if n > _EXP_HIGH:  # 2^128 is not a float32: 2 p 2^127 instead (up to exp(88.72), the largest float32)
        n, p = np.float32(_EXP_HIGH), p * np.float32(2.0)
    index = int(n) - _EXP_LOW if n == n else 0  # NaN: any entry; p is NaN
    return p * _POW2[index]


@njit(inline="always", **_FLAGS)
def sigmoid32(x: np.float32) -> np.float32:
    """The logistic function of a float32: 1 / (1 + exp32(-x))."""
    return np.float32(1.0) / (np.float32(1.0) + exp32(-x))
