"""The default pixel CNN's compiled convolutions (``policies.conv``): the RGB kernels (``ordered_conv1``,
``ordered_conv2``) and the general one (``ordered_conv``) against the equations written out with an exact
fused multiply-add, against each other bit for bit on random and CarRacing frames, twice; the features
against the original's CNN computed by torch (conv2d, tanh, then max-pool), within a few float32 ulps.
tests/test_pinned.py's pixel cases pin the numbers themselves.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

import policies.conv as conv
from envs import ProblemSpec
from policies import PolicySettings
from policies.conv import (
    ConvFeatures,
    max_pool2,
    ordered_conv,
    ordered_conv1,
    ordered_conv2,
    split_columns,
    split_phases,
)
from policies.elementary import _TANH_CLAMP, _TANH_P, _TANH_Q, tanh_in_place
from policies.elementary import rational_tanh as project_tanh
from policies.network import PIXEL_SIZE, conv_shapes

torch = pytest.importorskip("torch")  # in requirements.txt
RGB, HIDDEN, SIZE1, POOLED1, FULL2 = conv.RGB, conv.HIDDEN, conv.SIZE1, conv.POOLED1, conv.FULL2
COLUMNS, SLACK, WIDE1, WIDE2 = conv.COLUMNS, conv.SLACK, conv.WIDE1, conv.WIDE2
SHAPES = conv_shapes(RGB)
SIZES = [int(np.prod(shape)) for shape in SHAPES]


def car_racing_frames(count: int) -> list[np.ndarray]:
    """``count`` CarRacing-v3 observations (the network's input) under random actions, from seed 3."""
    problem = ProblemSpec(("CarRacing-v3",), PolicySettings("static")).build()
    env, frames = problem.envs[0], []
    try:
        observation, _ = env.reset(seed=3)
        env.action_space.seed(3)
        while len(frames) < count:
            frames.append(np.array(observation))
            observation, *_ = env.step(env.action_space.sample())
    finally:
        problem.close()
    return frames


def fma32(a: np.float32, b: np.float32, c: np.float32) -> np.float32:
    """a * b + c rounded once to the nearest float32 (ties to even), from the exact rational value; an
    exact zero is -0 only when the product and c are both -0 (IEEE 754)."""
    exact = Fraction(float(a)) * Fraction(float(b)) + Fraction(float(c))
    if exact == 0:
        negative_product = a * b == 0 and np.signbit(a) != np.signbit(b)
        return np.float32(-0.0) if negative_product and np.signbit(c) else np.float32(0.0)
    near = np.float32(float(exact))  # may be off by one ulp (rounded twice): the neighbours decide
    candidates = [np.nextafter(near, np.float32(-np.inf)), near, np.nextafter(near, np.float32(np.inf))]
    return min(candidates, key=lambda x: (abs(Fraction(float(x)) - exact), int(x.view(np.uint32)) & 1))


def reference_rows(planes: np.ndarray, weights: np.ndarray, stride: int, rows: list[int]) -> np.ndarray:
    """Rows ``rows`` of every output plane: per output, from +0, fma over the window's rows, columns,
    channels, in that order."""
    outs, channels, size, _ = weights.shape
    width = (planes.shape[2] - size) // stride + 1
    out = np.zeros((outs, len(rows), width), np.float32)
    for o in range(outs):
        for index, y in enumerate(rows):
            for x in range(width):
                total = np.float32(0.0)
                for ky in range(size):
                    for kx in range(size):
                        for c in range(channels):
                            total = fma32(weights[o, c, ky, kx], planes[c, stride * y + ky, stride * x + kx], total)
                out[o, index, x] = total
    return out


def run_kernels(frame: np.ndarray, vector: np.ndarray, pooled: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """conv1 of ``frame`` and conv2 of ``pooled`` (6 x 41 x 41) through the ordered kernels: the input
    flat and slack-ended, the outputs flat with rows of WIDE1 and WIDE2 floats (NaN before: every used
    output must be written)."""
    conv1, conv2 = (part.reshape(shape) for part, shape in zip(np.split(vector, [SIZES[0]]), SHAPES))
    flat_frame = np.zeros(frame.size + SLACK, np.float32)
    flat_frame[:frame.size] = frame.reshape(-1)
    planes1 = np.full(HIDDEN * SIZE1 * WIDE1, np.nan, np.float32)  # rows WIDE1 long, SIZE1 of them used
    ordered_conv1(planes1, flat_frame, conv1)
    columns = np.zeros((HIDDEN, POOLED1, 2, COLUMNS), np.float32)  # split_columns' layout
    columns[:, :, 0, :(POOLED1 + 1) // 2], columns[:, :, 1, :POOLED1 // 2] = pooled[:, :, 0::2], pooled[:, :, 1::2]
    planes2 = np.full(SHAPES[1][0] * FULL2 * WIDE2, np.nan, np.float32)
    ordered_conv2(planes2, columns.reshape(-1), conv2)
    return (planes1.reshape(HIDDEN, SIZE1, WIDE1)[:, :, :SIZE1],
            planes2.reshape(SHAPES[1][0], FULL2, WIDE2)[:, :, :FULL2])


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and np.array_equal(a.view(np.uint32), b.view(np.uint32))



def test_the_ordered_convolutions_are_the_equations():
    """Exactly the sums written out, each multiply-add rounded once, on rows at both edges and the middle;
    a black frame under negative weights sums to +0, as the equations say."""
    rng = np.random.default_rng(11)
    frame = rng.random((RGB, PIXEL_SIZE, PIXEL_SIZE), dtype=np.float32)
    pooled = rng.standard_normal((HIDDEN, POOLED1, POOLED1), dtype=np.float32)
    vector = rng.standard_normal(sum(SIZES), dtype=np.float32)
    conv1, conv2 = (part.reshape(shape) for part, shape in zip(np.split(vector, [SIZES[0]]), SHAPES))
    got1, got2 = run_kernels(frame, vector, pooled)
    rows1, rows2 = [0, 37, SIZE1 - 1], [0, 9, FULL2 - 1]
    assert same_bits(got1[:, rows1], reference_rows(frame, conv1, 1, rows1))
    assert same_bits(got2[:, rows2], reference_rows(pooled, conv2, 2, rows2))

    black, negative = np.zeros_like(frame), -np.abs(vector)
    got1, _ = run_kernels(black, negative, pooled)
    assert same_bits(got1[:, :1], reference_rows(black, negative[:SIZES[0]].reshape(SHAPES[0]), 1, [0]))
    assert not np.signbit(got1).any()


def general(planes: np.ndarray, weights: np.ndarray, stride: int) -> np.ndarray:
    """``ordered_conv`` of ``planes`` at ``stride``, through ``split_phases``."""
    channels, height, width = planes.shape
    phases = np.zeros((channels, height, stride, -(-width // stride)), np.float32)
    split_phases(planes, phases)
    size = weights.shape[2]
    out = np.full((weights.shape[0], (height - size) // stride + 1, (width - size) // stride + 1), np.nan,
                  np.float32)
    ordered_conv(out, phases, weights)
    return out


@pytest.mark.parametrize("channels", [1, 4])
def test_the_general_convolution_is_the_equations(channels):
    """Any channel count, stride 1 and 2: exactly the sums written out, in the same order as the RGB kernels."""
    rng = np.random.default_rng(channels)
    frame = rng.random((channels, PIXEL_SIZE, PIXEL_SIZE), dtype=np.float32)
    pooled = rng.standard_normal((HIDDEN, POOLED1, POOLED1), dtype=np.float32)
    (first, second) = conv_shapes(channels)
    conv1 = rng.standard_normal(first, dtype=np.float32)
    conv2 = rng.standard_normal(second, dtype=np.float32)
    rows1, rows2 = [0, 41, SIZE1 - 1], [0, 8, FULL2 - 1]
    assert same_bits(general(frame, conv1, 1)[:, rows1], reference_rows(frame, conv1, 1, rows1))
    assert same_bits(general(pooled, conv2, 2)[:, rows2], reference_rows(pooled, conv2, 2, rows2))


def test_the_general_convolution_is_the_rgb_kernels():
    """On RGB frames the two implementations give the same bits: outputs of every row, and the features."""
    rng = np.random.default_rng(12)
    frame = rng.random((RGB, PIXEL_SIZE, PIXEL_SIZE), dtype=np.float32)
    pooled = rng.standard_normal((HIDDEN, POOLED1, POOLED1), dtype=np.float32)
    vector = (rng.standard_normal(sum(SIZES)) * 3).astype(np.float32)
    conv1, conv2 = (part.reshape(shape) for part, shape in zip(np.split(vector, [SIZES[0]]), SHAPES))
    got1, got2 = run_kernels(frame, vector, pooled)
    assert same_bits(got1, general(frame, conv1, 1)) and same_bits(got2, general(pooled, conv2, 2))


def test_the_default_features_are_the_same_bits_on_both_paths_and_twice():
    """60 CarRacing frames and 10 random ones, three weight scales: the RGB path and the general one agree bit
    for bit, and a second instance (fresh buffers) gives the same bits; any dtype of frame is taken."""
    frames = car_racing_frames(60)
    rng = np.random.default_rng(13)
    frames += [rng.random((RGB, PIXEL_SIZE, PIXEL_SIZE), dtype=np.float32) for _ in range(10)]
    for scale in (1.0, 0.1, 10.0):
        vector = (rng.standard_normal(sum(SIZES)) * scale).astype(np.float32)
        first, second, reference = (ConvFeatures(vector, SHAPES), ConvFeatures(vector, SHAPES),
                                    ConvFeatures(vector, SHAPES, specialised=False))
        assert (first.path, reference.path) == ("ordered", "general")
        for frame in frames:
            expected = reference(frame).copy()
            assert same_bits(first(frame), expected) and same_bits(second(frame), expected)
        assert same_bits(first(frames[3].astype(np.float64)), reference(frames[3]))


def test_other_channel_counts_take_the_general_path():
    shapes = conv_shapes(4)
    vector = np.random.default_rng(14).standard_normal(sum(int(np.prod(s)) for s in shapes), dtype=np.float32)
    assert ConvFeatures(vector, shapes).path == "general"


def test_the_columns_are_the_pooled_planes_split():
    pooled = np.random.default_rng(15).standard_normal((HIDDEN, POOLED1, POOLED1), dtype=np.float32)
    columns = np.zeros((HIDDEN, POOLED1, 2, COLUMNS), np.float32)
    split_columns(pooled, columns)
    assert same_bits(columns[:, :, 0, :21], pooled[:, :, 0::2])
    assert same_bits(columns[:, :, 1, :20], pooled[:, :, 1::2])
    phases = np.zeros((HIDDEN, POOLED1, 2, 21), np.float32)
    split_phases(pooled, phases)
    assert same_bits(phases[:, :, 0], pooled[:, :, 0::2]) and same_bits(phases[:, :, 1, :20], pooled[:, :, 1::2])


def rational_tanh(x: np.ndarray) -> np.ndarray:
    """The project's rational tanh (``policies.kernels``), in numpy float32, term by term."""
    x = np.clip(x.astype(np.float32), -_TANH_CLAMP, _TANH_CLAMP)
    x2, p, q = x * x, np.float32(_TANH_P[0]), np.float32(_TANH_Q[0])
    for c in _TANH_P[1:]:
        p = p * x2 + np.float32(c)
    for c in _TANH_Q[1:]:
        q = q * x2 + np.float32(c)
    return x * p / q


def test_the_rational_tanh_is_the_formula_and_close_to_tanh():
    rng = np.random.default_rng(2)
    x = np.concatenate([rng.uniform(-9, 9, 20_000), rng.standard_normal(20_000) * 1e-3,
                        [0.0, -0.0, 7.9, 7.91, 20.0, -20.0, np.inf, -np.inf]]).astype(np.float32)
    got = x.copy()
    tanh_in_place(got)
    np.testing.assert_array_equal(got, rational_tanh(x))
    assert np.abs(got.astype(np.float64) - np.tanh(x.astype(np.float64))).max() < 5e-7  # 4.1e-7 over all floats
    assert np.isnan(project_tanh(np.float32(np.nan)))
    assert math.copysign(1.0, project_tanh(np.float32(-0.0))) == -1.0


def test_the_features_are_the_pooled_sums_tanh():
    """The features are max_pool2 of the convolutions, then the rational tanh, exactly: conv1's planes from
    the kernels, pooled and tanh'd in numpy, give conv2's input; conv2's, the features."""
    rng = np.random.default_rng(16)
    frame = rng.random((RGB, PIXEL_SIZE, PIXEL_SIZE), dtype=np.float32)
    vector = rng.standard_normal(sum(SIZES), dtype=np.float32)
    conv1, conv2 = (part.reshape(shape) for part, shape in zip(np.split(vector, [SIZES[0]]), SHAPES))
    pooled1 = rational_tanh(max_pool2(general(frame, conv1, 1)))
    expected = rational_tanh(max_pool2(general(pooled1, conv2, 2))).reshape(-1)
    assert same_bits(ConvFeatures(vector, SHAPES)(frame), expected)


def test_the_features_are_the_original_cnn_within_float32_rounding():
    """Against the original's CNN as torch computes it (conv2d, tanh, then max-pool): within 1e-5 on CarRacing
    frames for N(0, 1) and 0.1 N(0, 1) weights (measured: 3.5e-6 at most, the rational tanh's 4 ulps carried through
    conv2)."""
    frames = car_racing_frames(20)
    rng = np.random.default_rng(17)
    conv2d = torch.nn.functional.conv2d
    for scale in (1.0, 0.1):
        vector = (rng.standard_normal(sum(SIZES)) * scale).astype(np.float32)
        conv1, conv2 = (torch.from_numpy(part.reshape(shape).copy()) for part, shape in
                        zip(np.split(vector, [SIZES[0]]), SHAPES))
        features = ConvFeatures(vector, SHAPES)
        for frame in frames:
            with torch.inference_mode():
                x = torch.from_numpy(np.ascontiguousarray(frame, dtype=np.float32))[None]
                hidden = torch.nn.functional.max_pool2d(conv2d(x, conv1).tanh(), 2)
                expected = torch.nn.functional.max_pool2d(conv2d(hidden, conv2, stride=2).tanh(), 2).reshape(-1)
            assert np.abs(features(frame) - expected.numpy()).max() < 1e-5
