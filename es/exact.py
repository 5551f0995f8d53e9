"""Element-wise exp, log, log2 and whole powers in float64, and the Euclidean norm: the strategies' own
arithmetic, whose bits depend neither on the CPU nor on the C library.

numpy's float64 ``exp`` and ``log`` run a loop of numpy's own where the CPU has AVX-512 and the C library's
functions elsewhere; glibc picks its ``exp``, ``log``, ``log2`` and ``pow`` by the CPU's features when a program
starts (on x86-64, a CPU with FMA and AVX2 and one without differ in the last bit of about one ``exp`` in 1,500,
and in glibc's ``log2`` of 83,507, of 0.9^348 ...); ``numpy.linalg.norm`` sums through BLAS, whose kernel, and
so the order of its sum, depends on the CPU. The strategies' updates, the fitness shapings, the NES utilities
and Adam's bias corrections use these functions instead: each is a fixed sequence of IEEE 754 additions,
subtractions, multiplications and divisions on float64 numpy arrays (each operation one ufunc call, so
nothing is fused or reordered), the same bits on every machine.

- **Double-double arithmetic** (Dekker 1971): a value is an unevaluated sum hi + lo of two float64 numbers,
  about 106 bits; ``_two_sum`` and ``_two_product`` give a sum's and a product's rounding error exactly.
- ``exp``: exp(x) = 2^m 2^(j/64) exp(r) with n = 64 m + j = round(64 x / ln 2) and r = x - n ln2/64 in double-
  double (Cody & Waite 1980: ln2/64 in three parts; |r| <= 0.0055); 2^(j/64) from a table (Tang 1989), exp(r)
  by its Taylor polynomial of degree 10, the terms of degree 5 to 10 in float64, the others by Horner's scheme
  in double-double. The double-double's relative error is below 2^-95 (2^-97.4 at most, measured), so the
  result is the correctly rounded exp(x) unless exp(x) lies within 2^-42 ulp of a midpoint between two
  floats: correctly rounded on every input tested (``tests/test_exact.py``, against ``decimal`` at 50
  digits). Subnormal results (x < -708.39) are rounded twice: within 1 ulp. inf from 709.79, 0 below
  -745.14, NaN for NaN.
- ``log`` and ``log2``: x = 2^e m, m in [1, 2); m's first 7 bits pick c ~ 1/m from a table of 128, so that
  r = m c - 1 (exact in double-double) is below 2^-7; log(x) = e ln 2 - log(c) + log1p(r), log1p(r) by its
  Taylor polynomial of degree 15 (degrees 7 to 15 in float64, the others in double-double). The table's
  entries for m near 1 and near 2 are c = 1 and c = 1/2 exactly, so that log(x) keeps its relative accuracy
  near x = 1. The same bound as ``exp``, 2^-95 (2^-97.4 measured, near x = 1): correctly rounded on every
  input tested, among them log and log2 of every rank up to 8,192 and of lambda/2 + 1 (the NES and SNES
  utilities), and log2 of every power of two exactly. -inf for 0, NaN below 0 and for NaN, inf for inf.
- ``power(base, n)``: base^n for a whole n >= 0 by repeated squaring in double-double (Adam's beta^t). Each
  squaring doubles the relative error: below n 2^-105 where the result is above 2^-960 (n 2^-106.9 at most,
  measured for bases in [0.5, 1) and n < 2^20), so correctly rounded for the generations of any run on every
  input tested; smaller results (which Adam only subtracts from 1) within 1 ulp.
- The tables (2^(j/64), log(c)) are computed once, when the module is imported, with ``decimal``'s correctly
  rounded ``exp`` and ``ln`` at 50 digits: integer arithmetic, the same on every machine.
- ``norm``: sqrt(sum of squares), the sum in numpy's pairwise order, which numpy's code fixes whatever the CPU
  (``math.sqrt`` is correctly rounded by IEEE 754).

Where the C library rounds the other way these give other bits than it: on this project's reference machine
(glibc 2.36 with FMA), exp on about one input in 1,300, log2 of 1,621, log of 9,170, 0.9^3270. No function
warns: an overflow to inf, a log of 0 or of a negative number give the IEEE results silently, and the caller
decides what they mean.
"""

from __future__ import annotations

import decimal
import math
from fractions import Fraction

import numpy as np

# --- double-double arithmetic (Dekker 1971; Shewchuk 1997): each line one IEEE operation, in this order


def _two_sum(a, b):
    """(s, e) with s = fl(a + b) and s + e = a + b exactly."""
    total = a + b
    b_part = total - a
    return total, (a - (total - b_part)) + (b - b_part)


def _fast_two_sum(a, b):
    """(s, e) with s = fl(a + b) and s + e = a + b exactly, where |a| >= |b| or a = 0."""
    total = a + b
    return total, b - (total - a)


_SPLITTER = 134217729.0  # 2^27 + 1: splits a float64 into two halves of 26 bits


def _split(a):
    scaled = _SPLITTER * a
    high = scaled - (scaled - a)
    return high, a - high


def _two_product(a, b):
    """(p, e) with p = fl(a b) and p + e = a b exactly (|a|, |b| below 2^995)."""
    product = a * b
    a_high, a_low = _split(a)
    b_high, b_low = _split(b)
    return product, ((a_high * b_high - product) + a_high * b_low + a_low * b_high) + a_low * b_low


def _dd_mul(a_high, a_low, b_high, b_low):
    product, error = _two_product(a_high, b_high)
    error = error + (a_high * b_low + a_low * b_high)
    return _fast_two_sum(product, error)


def _dd_add(a_high, a_low, b_high, b_low):
    total, error = _two_sum(a_high, b_high)
    low_total, low_error = _two_sum(a_low, b_low)
    total, error = _fast_two_sum(total, error + low_total)
    return _fast_two_sum(total, error + low_error)


def _horner_dd(x_high, x_low, head, coefficients):
    """head x^k + c_{k-1} x^(k-1) + ... + c_0 by Horner's scheme in double-double; ``coefficients`` are
    (hi, lo) pairs from c_{k-1} down to c_0."""
    high, low = head, np.zeros_like(head)
    for c_high, c_low in coefficients:
        high, low = _dd_mul(high, low, x_high, x_low)
        high, low = _dd_add(high, low, c_high, c_low)
    return high, low


# --- the constants and tables, exact rationals rounded once


def _double_double(value: Fraction) -> tuple[float, float]:
    high = float(value)  # correctly rounded
    return high, float(value - Fraction(high))


def _chopped(value: Fraction, bits: int) -> float:
    """A positive ``value`` rounded to ``bits`` significant bits (so that its product with a small integer is
    exact)."""
    exponent = value.numerator.bit_length() - value.denominator.bit_length()  # floor(log2 value), or one above
    if value < Fraction(2) ** exponent:
        exponent -= 1
    return float(round(value * Fraction(2) ** (bits - 1 - exponent)) * Fraction(2) ** (exponent - bits + 1))


_CONTEXT = decimal.Context(prec=50)


def _ln(value: Fraction) -> Fraction:
    return Fraction(_CONTEXT.ln(_CONTEXT.divide(decimal.Decimal(value.numerator), decimal.Decimal(value.denominator))))


_LN2 = _ln(Fraction(2))
LN2 = _double_double(_LN2)
LOG2E = _double_double(1 / _LN2)

_TABLE_BITS = 6  # exp's table: 2^(j/64)
_STEPS = 1 << _TABLE_BITS
_EXP_TABLE = np.array([_double_double(Fraction(_CONTEXT.exp(_CONTEXT.multiply(
    decimal.Decimal(j) / _STEPS, _CONTEXT.ln(decimal.Decimal(2)))))) for j in range(_STEPS)]).T
_INV_STEP = float(_STEPS / _LN2)  # 64 / ln 2: only chooses n
_STEP = _LN2 / _STEPS
_STEP1 = _chopped(_STEP, 35)  # n ln2/64 = n (_STEP1 + _STEP2 + _STEP3), the first two products exact for |n| < 2^17
_STEP2 = _chopped(_STEP - Fraction(_STEP1), 35)
_STEP3 = float(_STEP - Fraction(_STEP1) - Fraction(_STEP2))
_EXP_DD = [_double_double(Fraction(1, math.factorial(k))) for k in range(5)][::-1]  # 1/4! ... 1/0!
_EXP_PLAIN = [1.0 / math.factorial(k) for k in range(10, 4, -1)]  # 1/10! ... 1/5!, rounded once each
_X_LIMIT = 750.0  # exp(+-750) is inf and 0 in float64; the clamp keeps n and the exponents small


def _power_of_two(exponent: np.ndarray) -> np.ndarray:
    """2^k for whole k in [-1022, 1023], built from its bits."""
    return ((exponent.astype(np.int64) + 1023) << 52).view(np.float64)


def _as_array(values) -> np.ndarray:
    return np.array(values, dtype=np.float64)  # a copy, so the callers' arrays are never written


def _exp_double_double(x: np.ndarray):
    """exp(x) = (high + low) 2^m for finite x in [-750, 750]: (high, low, m)."""
    n = np.rint(x * _INV_STEP)
    r_high, r_low = _two_sum(x - n * _STEP1, -(n * _STEP2))  # x - n _STEP1 is exact (Sterbenz)
    r_high, r_low = _fast_two_sum(r_high, r_low - n * _STEP3)
    tail = np.full_like(x, _EXP_PLAIN[0])
    for coefficient in _EXP_PLAIN[1:]:
        tail = tail * r_high + coefficient
    high, low = _horner_dd(r_high, r_low, tail, _EXP_DD)
    m = np.floor(n / _STEPS)
    j = (n - m * _STEPS).astype(np.int64)
    high, low = _dd_mul(high, low, _EXP_TABLE[0][j], _EXP_TABLE[1][j])
    return high, low, m


def exp(values) -> np.ndarray:
    """e^x of each value, as the module's docstring says."""
    x = _as_array(values)
    nan = np.isnan(x)
    high, _, m = _exp_double_double(np.clip(np.where(nan, 0.0, x), -_X_LIMIT, _X_LIMIT))
    half = np.floor(m / 2)
    with np.errstate(over="ignore", under="ignore"):  # inf above exp's range, 0 or subnormal below it: IEEE's
        result = (high * _power_of_two(half)) * _power_of_two(m - half)
    return np.where(nan, np.nan, result)


_LOG_BITS = 7  # log's table: 128 intervals of m in [1, 2)
_INTERVALS = 1 << _LOG_BITS
_HIGH_HALF = 53  # intervals from 1 + 53/128 (above sqrt 2) use m/2 and e + 1, so log(m) stays small


def _log_table() -> tuple[np.ndarray, ...]:
    inverses, shifts, logs, log2s = [], [], [], []
    for i in range(_INTERVALS):
        shift = 1 if i >= _HIGH_HALF else 0
        inverse = 1.0 / (1.0 + (i + 0.5) / _INTERVALS)  # one IEEE division: the same everywhere
        if i == 0:
            inverse = 1.0  # m near 1: r = m - 1, log(m) = log1p(r), no cancellation
        elif i == _INTERVALS - 1:
            inverse = 0.5  # m near 2 (x just below a power of two): r = m/2 - 1
        value = -_ln(Fraction(inverse) * 2**shift)  # log(1 / (c 2^shift)) = log(m) - log1p(r) - shift ln 2
        inverses.append(inverse)
        shifts.append(shift)
        logs.append(_double_double(value))
        log2s.append(_double_double(value / _LN2))
    return (np.array(inverses), np.array(shifts, dtype=np.float64), *np.array(logs).T, *np.array(log2s).T)


_LOG_INVERSE, _LOG_SHIFT, _LOG_HIGH, _LOG_LOW, _LOG2_HIGH, _LOG2_LOW = _log_table()
_LOG1P_DD = [_double_double(Fraction((-1) ** (k + 1), k)) for k in range(1, 7)][::-1]  # -1/6 ... 1/1
_LOG1P_PLAIN = [(-1) ** (k + 1) / k for k in range(15, 6, -1)]  # 1/15 ... 1/7, rounded once each
_MANTISSA = (1 << 52) - 1
_SUBNORMAL_SCALE = 2.0 ** 54


def _log_parts(values):
    """For each x: (e, log(1/c) in the base's table ..., log1p(r) as a double-double) and masks of the
    special values, with log(x) = e ln 2 + table + log1p(r)."""
    x = _as_array(values)
    nan, negative, zero, infinite = np.isnan(x), x < 0, x == 0, np.isposinf(x)
    special = nan | negative | zero | infinite
    x = np.where(special, 1.0, x)
    subnormal = x < 2.0 ** -1022
    x = x * np.where(subnormal, _SUBNORMAL_SCALE, 1.0)
    bits = x.view(np.int64)
    exponent = ((bits >> 52) - 1023).astype(np.float64) - np.where(subnormal, 54.0, 0.0)
    mantissa = ((bits & _MANTISSA) | (1023 << 52)).view(np.float64)  # m in [1, 2)
    index = (bits & _MANTISSA) >> (52 - _LOG_BITS)
    product, error = _two_product(mantissa, _LOG_INVERSE[index])
    r_high, r_low = _two_sum(product - 1.0, error)  # product - 1 is exact (Sterbenz)
    tail = np.full_like(x, _LOG1P_PLAIN[0])
    for coefficient in _LOG1P_PLAIN[1:]:
        tail = tail * r_high + coefficient
    high, low = _horner_dd(r_high, r_low, tail, _LOG1P_DD)
    high, low = _dd_mul(high, low, r_high, r_low)  # log1p(r)
    masks = (nan | negative, zero, infinite)
    return exponent + _LOG_SHIFT[index], index, (high, low), masks


def _with_specials(result: np.ndarray, masks) -> np.ndarray:
    not_a_number, zero, infinite = masks
    return np.where(not_a_number, np.nan, np.where(zero, -np.inf, np.where(infinite, np.inf, result)))


def _log_double_double(values):
    """log(x) as a double-double (high, low), and the special values' masks."""
    exponent, index, (high, low), masks = _log_parts(values)
    scaled_high, scaled_low = _two_product(exponent, LN2[0])
    scaled_low = scaled_low + exponent * LN2[1]
    part_high, part_low = _dd_add(_LOG_HIGH[index], _LOG_LOW[index], high, low)
    return (*_dd_add(scaled_high, scaled_low, part_high, part_low), masks)


def _log2_double_double(values):
    """log2(x) as a double-double (high, low), and the special values' masks."""
    exponent, index, (high, low), masks = _log_parts(values)
    high, low = _dd_mul(high, low, *LOG2E)
    part_high, part_low = _dd_add(_LOG2_HIGH[index], _LOG2_LOW[index], high, low)
    total, error = _two_sum(exponent, part_high)
    return (*_fast_two_sum(total, error + part_low), masks)


def log(values) -> np.ndarray:
    """The natural logarithm of each value, as the module's docstring says."""
    high, _, masks = _log_double_double(values)
    return _with_specials(high, masks)


def log2(values) -> np.ndarray:
    """The base-2 logarithm of each value, as the module's docstring says (exact for powers of two)."""
    high, _, masks = _log2_double_double(values)
    return _with_specials(high, masks)


def power(base: float, exponent: int) -> float:
    """base^exponent for a float base and a whole exponent >= 0, by repeated squaring in double-double."""
    if exponent < 0:
        raise ValueError(f"power takes a whole exponent >= 0, got {exponent}")
    square_high, square_low = np.float64(base), np.float64(0.0)
    high, low = np.float64(1.0), np.float64(0.0)
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        while exponent:
            if exponent & 1:
                high, low = _dd_mul(high, low, square_high, square_low)
            exponent >>= 1
            if exponent:
                square_high, square_low = _dd_mul(square_high, square_low, square_high, square_low)
    return float(high)


_SQUARES_LOW = 2.0 ** -960  # a sum of squares below it may have lost bits to subnormal squares


def norm(values: np.ndarray) -> float:
    """sqrt(sum of squares), the sum pairwise in float64; where that sum overflows to inf or is too small for
    its squares' bits, largest * sqrt(sum of (value / largest)^2) instead, so a finite vector's norm is finite
    and a non-zero vector's is not 0."""
    values = np.asarray(values, dtype=np.float64)
    with np.errstate(over="ignore", under="ignore"):
        total = float(np.sum(np.square(values)))
        if _SQUARES_LOW <= total < math.inf or not np.isfinite(values).all():
            return math.sqrt(total)
        largest = float(np.max(np.abs(values))) if values.size else 0.0
        if largest == 0.0:
            return 0.0
        return largest * math.sqrt(float(np.sum(np.square(values / largest))))
