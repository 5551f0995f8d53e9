"""The strategies' float64 functions (``es.exact``) against references computed with ``decimal`` at 50 digits
(its exp and ln are correctly rounded) and exact rationals: correctly rounded over the ranges the strategies
use, the double-double before its last rounding within its stated 2^-95, the special values without a
warning, and the same bits under the C library's and numpy's other code paths.
"""

from __future__ import annotations

import decimal
import hashlib
import json
import math
import os
import platform
import subprocess
import sys
import warnings
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from es import exact

ROOT = Path(__file__).resolve().parents[1]
CONTEXT = decimal.Context(prec=50)
BOUND = Fraction(1, 2**95)  # the relative error of the double-double the module's docstring states


def d(value: float) -> decimal.Decimal:
    return decimal.Decimal(value)  # exact


def ln(value: float) -> decimal.Decimal:
    return CONTEXT.ln(d(value))


def log2(value: float) -> decimal.Decimal:
    return CONTEXT.divide(ln(value), CONTEXT.ln(decimal.Decimal(2)))


def e_to(value: float) -> decimal.Decimal:
    return CONTEXT.exp(d(value))


def rounded(references) -> np.ndarray:
    return np.array([float(reference) for reference in references])  # 50 digits, then rounded once


def relative_errors(high, low, references, scale=None) -> list[Fraction]:
    """|high + low - reference| / |reference|, in exact rationals."""
    scale = np.zeros(len(references)) if scale is None else scale
    errors = []
    for h, lo, m, reference in zip(high.tolist(), low.tolist(), scale.tolist(), references):
        reference = Fraction(reference) / Fraction(2) ** int(m)
        errors.append(abs(Fraction(h) + Fraction(lo) - reference) / abs(reference))
    return errors


RNG_SEED = 20_260_101
SAMPLES = 4000


def exp_inputs() -> np.ndarray:
    rng = np.random.default_rng(RNG_SEED)
    return np.concatenate([rng.uniform(-708.0, 709.7, SAMPLES), rng.uniform(-2.0, 2.0, SAMPLES),
                           rng.uniform(-1e-6, 1e-6, SAMPLES // 4), [0.0, -0.0, 1.0, -1.0, 709.78, -708.39]])


def log_inputs() -> np.ndarray:
    rng = np.random.default_rng(RNG_SEED + 1)
    return np.concatenate([exact.exp(rng.uniform(-740.0, 709.0, SAMPLES)), 1 + rng.uniform(-0.02, 0.02, SAMPLES),
                           1 + rng.integers(-2**20, 2**20, SAMPLES // 4) * 2.0**-52,
                           rng.uniform(0.0, 2.2e-308, SAMPLES // 4), [5e-324, 1.7976931348623157e308]])


def test_exp_is_correctly_rounded():
    x = exp_inputs()
    references = [e_to(value) for value in x.tolist()]
    np.testing.assert_array_equal(exact.exp(x), rounded(references))
    high, low, m = exact._exp_double_double(x)
    assert max(relative_errors(high, low, references, m)) < BOUND


@pytest.mark.parametrize("name", ["log", "log2"])
def test_logarithms_are_correctly_rounded(name):
    x = log_inputs()
    references = [(ln if name == "log" else log2)(value) for value in x.tolist()]
    np.testing.assert_array_equal(getattr(exact, name)(x), rounded(references))
    high, low, _ = getattr(exact, f"_{name}_double_double")(x)
    assert max(relative_errors(high, low, references)) < BOUND


def test_the_logarithms_of_ranks_are_correctly_rounded():
    """What the NES and SNES utilities take: log and log2 of the ranks 1..lambda and of lambda/2 + 1, for every
    population up to 2^13 and sampled to 2^20; among them 1621, whose log2 the C library on a CPU with FMA
    rounds the wrong way, and 83,507, whose log2 it rounds the wrong way on a CPU without FMA."""
    ranks = np.concatenate([np.arange(1, 2**13 + 1), np.random.default_rng(3).integers(2**13, 2**20, 3000),
                            [1621, 3242, 83_507, 167_014]]).astype(np.float64)
    for values in (ranks, ranks / 2 + 1):
        np.testing.assert_array_equal(exact.log2(values), rounded([log2(value) for value in values.tolist()]))
        np.testing.assert_array_equal(exact.log(values), rounded([ln(value) for value in values.tolist()]))


def test_powers_of_two_have_exact_logarithms_and_exp_hits_its_ends():
    powers = np.ldexp(1.0, np.arange(-1074, 1024))
    np.testing.assert_array_equal(exact.log2(powers), np.arange(-1074, 1024, dtype=np.float64))
    assert exact.log(1.0) == 0.0 and exact.log2(1.0) == 0.0 and exact.exp(0.0) == 1.0
    assert exact.exp(709.782712893384) == 1.7976931348622732e308  # the largest exp below float64's limit
    assert exact.exp(709.79) == np.inf and exact.exp(-745.2) == 0.0
    assert exact.exp(-745.13) == 5e-324  # the smallest subnormal


def test_subnormal_results_are_within_one_ulp():
    x = np.random.default_rng(5).uniform(-745.1, -708.4, 2000)
    got = exact.exp(x)
    spacing = 2.0**-1074
    errors = [abs(Fraction(value) - Fraction(e_to(argument))) / Fraction(spacing)
              for value, argument in zip(got.tolist(), x.tolist())]
    assert max(errors) <= 1


def test_special_values_give_ieee_results_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = exact.exp(np.array([np.inf, -np.inf, np.nan, 1e308, -1e308]))
        logs = exact.log(np.array([0.0, -0.0, -1.0, -np.inf, np.nan, np.inf]))
        log2s = exact.log2(np.array([0.0, -1.0, np.nan, np.inf]))
    np.testing.assert_array_equal(got, [np.inf, 0.0, np.nan, np.inf, 0.0])
    np.testing.assert_array_equal(logs, [-np.inf, -np.inf, np.nan, np.nan, np.nan, np.inf])
    np.testing.assert_array_equal(log2s, [-np.inf, np.nan, np.nan, np.inf])


def test_shapes_scalars_and_the_callers_arrays():
    values = np.random.default_rng(0).uniform(0.01, 50.0, size=(7, 3))
    kept = values.copy()
    for function in (exact.exp, exact.log, exact.log2):
        got = function(values)
        assert got.shape == values.shape and got.dtype == np.float64
        assert function(3.0).shape == () and float(function(3.0)) == function(np.array([3.0]))[0]
    np.testing.assert_array_equal(values, kept)


@pytest.mark.parametrize("base", [0.9, 0.99, 0.999, 0.9999, 0.5, 0.123456789])
def test_power_is_correctly_rounded(base):
    """Adam's beta^t: among the exponents, 3270 (0.9), 503 (0.99), 494 (0.9999) and 2904 (0.999), which the C
    library's pow rounds the wrong way on a CPU with FMA."""
    exponents = sorted({*range(0, 200), *range(200, 20_000, 97), 3270, 503, 494, 2904})
    exact_values = [Fraction(base) ** t for t in exponents]
    got = [exact.power(base, t) for t in exponents]
    normal = [(value, float(reference)) for value, reference in zip(got, exact_values) if reference >= 2**-960]
    assert len(normal) > 100 and all(value == want for value, want in normal)  # correctly rounded
    tiny = [abs(Fraction(value) - reference) / Fraction(math.ulp(float(reference)))
            for value, reference in zip(got, exact_values) if reference < 2**-960]
    assert all(error <= 1 for error in tiny)  # where the low part has lost bits: within an ulp
    assert exact.power(0.0, 0) == 1.0 and exact.power(0.0, 5) == 0.0
    with pytest.raises(ValueError, match="whole exponent >= 0"):
        exact.power(base, -1)


def test_norm_is_the_square_root_of_numpys_pairwise_sum():
    values = np.random.default_rng(1).standard_normal(100_003)
    assert exact.norm(values) == math.sqrt(float(np.sum(values * values)))
    assert exact.norm(np.float32([3.0, 4.0])) == 5.0


def test_norm_of_huge_and_tiny_vectors_is_scaled_not_inf_or_0():
    """A sum of squares beyond float64's range (ClipUp's velocity after a huge --pgpe_lr) or below its normal
    numbers: the norm scaled by the largest value, without a warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert exact.norm(np.array([3e300, 4e300])) == 5e300
        assert exact.norm(np.array([3e-300, 4e-300])) == 5e-300
        assert exact.norm(np.zeros(3)) == 0.0 and exact.norm(np.zeros(0)) == 0.0
        assert exact.norm(np.array([1.0, np.inf])) == np.inf and np.isnan(exact.norm(np.array([1.0, np.nan])))


def bits_digest() -> str:
    """A digest of exp, log, log2 and power over inputs the C library's paths round differently."""
    rng = np.random.default_rng(9)
    digest = hashlib.sha256()
    digest.update(exact.exp(rng.uniform(-700.0, 700.0, 20_000)).tobytes())
    for function in (exact.log, exact.log2):
        digest.update(function(exact.exp(rng.uniform(-700.0, 700.0, 20_000))).tobytes())  # (np.exp: the CPU's)
        digest.update(function(np.arange(1.0, 200_000.0)).tobytes())
    digest.update(np.array([exact.power(0.9, t) for t in range(1, 5000)]).tobytes())
    return digest.hexdigest()


def c_library_digest() -> str:
    """A digest of the C library's exp (Python's math) over the same kind of inputs."""
    values = np.random.default_rng(9).uniform(-700.0, 700.0, 20_000).tolist()
    return hashlib.sha256(np.array([math.exp(value) for value in values]).tobytes()).hexdigest()


def glibc_with_fma() -> bool:
    """glibc on x86-64 taking its functions' FMA code: a CPU with FMA and AVX2, nothing masked."""
    try:
        flags = set(next(line.split(":", 1)[1].split() for line in Path("/proc/cpuinfo").read_text().splitlines()
                         if line.startswith("flags")))
    except (OSError, StopIteration):
        return False
    return (platform.libc_ver()[0] == "glibc" and platform.machine() == "x86_64" and {"fma", "avx2"} <= flags
            and "glibc.cpu.hwcaps" not in os.environ.get("GLIBC_TUNABLES", ""))


# the code paths a CPU without AVX-512, or without FMA and AVX2, makes numpy and the C library take
PATHS = {
    "numpy without AVX-512": {"NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR"},
    "numpy without AVX2": {"NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"},
    "glibc without FMA": {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX"},
}


def test_the_same_bits_on_the_c_librarys_and_numpys_other_paths():
    """Each path in a child process (glibc reads its tunables when a program starts): the digest of this one.
    Where glibc runs its FMA code here, its own exp gives other bits on the path without FMA: the path is
    taken, and the C library's functions could not stand in for these."""
    code = ("from tests.test_exact import bits_digest, c_library_digest; print(bits_digest()); "
            "print(c_library_digest())")
    for name, env in PATHS.items():
        done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env={**os.environ, **env},
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-3000:]
        ours, c_library = done.stdout.strip().splitlines()[-2:]
        assert ours == bits_digest(), name
        if "GLIBC_TUNABLES" in env and glibc_with_fma():
            assert c_library != c_library_digest(), name


def test_glibc_differences_counts_what_the_two_paths_give(tmp_path):
    """benchmarks/glibc_differences.py: where glibc takes its FMA code here, the path without it gives other exp
    bits on some inputs, and none where both paths are the same code; the counts repeat from run to run."""
    def record() -> dict:
        folder = tmp_path / str(len(list(tmp_path.iterdir())))
        done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "glibc_differences.py"), "--values", "20000",
                               "--tracks", "3", "--results", str(folder)], cwd=ROOT, capture_output=True, text=True,
                              timeout=600)
        assert done.returncode == 0, done.stderr[-3000:]
        [path] = folder.glob("glibc_differences-*.json")
        return json.loads(path.read_text())

    first, second = record(), record()
    counts = {name: measure["values"] for name, measure in first["measures"].items()}
    assert counts == {name: measure["values"] for name, measure in second["measures"].items()}
    assert set(counts) == {"exp", "log", "sin", "cos", "atan2", "pow", "tracks"} and first["timed"] is False
    assert (counts["exp"][0] > 0) == glibc_with_fma()
    rows = first["notes"]["differences"]["rows"]
    assert [row[2] for row in rows] == [f"{int(counts[name][0]):,} of {20000 if name != 'tracks' else 3:,}"
                                        for name in counts]
