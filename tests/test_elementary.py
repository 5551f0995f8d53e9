"""The networks' elementary functions (``policies.elementary``): each the formula written out in numpy float32
term by term, bit for bit; exp within 1.2 ulp of exp over the normal range; the special values. The strategies'
float64 functions (``es.exact``) are tested in tests/test_exact.py.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from policies.elementary import _E, _EXP_HIGH, _EXP_LOW, _LN2_HIGH, _LN2_LOW, _LOG2E, exp32, sigmoid32


@njit(error_model="numpy")
def exp_all(values, out):
    for index in range(values.size):
        out[index] = exp32(values[index])


@njit(error_model="numpy")
def sigmoid_all(values, out):
    for index in range(values.size):
        out[index] = sigmoid32(values[index])


def reference_exp(x: np.ndarray) -> np.ndarray:
    """exp32's formula in numpy float32, the operations in the same order."""
    x = np.clip(x.astype(np.float32), np.float32(-104.0), np.float32(89.0))
    n = np.floor(x * _LOG2E + np.float32(0.5))
    r = (x - n * _LN2_HIGH) - n * _LN2_LOW
    p = np.full_like(x, _E[0])
    for coefficient in _E[1:]:
        p = p * r + coefficient
    big = n > _EXP_HIGH
    p = np.where(big, p * np.float32(2.0), p)
    n = np.where(big, np.float32(_EXP_HIGH), n)
    return p * np.ldexp(1.0, n.astype(np.int64)).astype(np.float32)


def exp_of(values: np.ndarray) -> np.ndarray:
    out = np.empty_like(values)
    exp_all(values, out)
    return out


def test_exp_is_its_formula_and_within_1_2_ulp():
    x = np.linspace(-103.0, 88.72, 2_000_001).astype(np.float32)
    got = exp_of(x)
    np.testing.assert_array_equal(got.view(np.uint32), reference_exp(x).view(np.uint32))
    exact_values = np.exp(x.astype(np.float64))
    normal = (exact_values > np.finfo(np.float32).tiny) & (exact_values < np.finfo(np.float32).max)
    spacing = np.spacing(exact_values[normal].astype(np.float32)).astype(np.float64)
    assert (np.abs(got[normal] - exact_values[normal]) / spacing).max() < 1.25
    assert _EXP_LOW == -151


def test_exp_special_values():
    x = np.float32([0.0, -0.0, -104.0, -200.0, 88.72, 88.73, 100.0, np.inf, -np.inf, np.nan])
    got = exp_of(x)
    assert got[0] == got[1] == 1.0
    assert got[2] == 0.0 and got[3] == 0.0 and got[8] == 0.0
    assert np.isfinite(got[4]) and got[4] > 3.39e38  # exp(88.72): within float32's range
    assert np.isinf(got[5]) and np.isinf(got[6]) and np.isinf(got[7])
    assert np.isnan(got[9])


def test_sigmoid_is_one_over_one_plus_exp():
    x = np.linspace(-30, 30, 10_001).astype(np.float32)
    got = np.empty_like(x)
    sigmoid_all(x, got)
    expected = np.float32(1.0) / (np.float32(1.0) + exp_of(-x))
    np.testing.assert_array_equal(got.view(np.uint32), expected.view(np.uint32))
    assert np.abs(got - 1 / (1 + np.exp(-x.astype(np.float64)))).max() < 2e-7
