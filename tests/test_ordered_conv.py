"""The default pixel CNN's compiled convolutions in torch's order (``policies.conv.ordered_conv1``,
``ordered_conv2``): against the equations written out with an exact fused multiply-add, against torch's
``conv2d`` bit for bit, the features against torch's path on random and CarRacing frames, twice;
and the check (``torch_order_holds``) that picks the path, its refusal of another order or of a tanh
that the pooling cannot go before, and what runs when it fails. tests/test_pinned.py's pixel cases pin
the numbers themselves.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

import policies.conv as conv
from policies.conv import ConvFeatures, max_pool2, ordered_conv1, ordered_conv2, split_columns, torch_order_holds
from policies.kernels import _TANH_CLAMP, _TANH_P, _TANH_Q
from policies.network import PIXEL_SIZE, conv_shapes
from tests.test_fast_conv import car_racing_frames

torch = pytest.importorskip("torch")  # in requirements.txt
RGB, HIDDEN, SIZE1, POOLED1, FULL2 = conv.RGB, conv.HIDDEN, conv.SIZE1, conv.POOLED1, conv.FULL2
COLUMNS, SLACK, WIDE1, WIDE2 = conv.COLUMNS, conv.SLACK, conv.WIDE1, conv.WIDE2
SHAPES = conv_shapes(RGB)
SIZES = [int(np.prod(shape)) for shape in SHAPES]
NOT_HERE = "this CPU's torch sums its convolutions in another order: the default runs torch's own path"


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


@pytest.mark.skipif(not torch_order_holds(), reason=NOT_HERE)
@pytest.mark.parametrize("scale", [1.0, 0.05, 40.0])
def test_the_ordered_convolutions_are_torchs_conv2d(scale):
    rng = np.random.default_rng(int(scale * 100))
    frames = [rng.random((RGB, PIXEL_SIZE, PIXEL_SIZE), dtype=np.float32) for _ in range(4)]
    frames += [np.floor(frames[0] * 4) / 4, np.zeros_like(frames[0])]  # repeated values and exact zeros
    for frame in frames:
        vector = (rng.standard_normal(sum(SIZES)) * scale).astype(np.float32)
        pooled = rng.standard_normal((HIDDEN, POOLED1, POOLED1), dtype=np.float32)
        conv1, conv2 = (torch.from_numpy(part.reshape(shape)) for part, shape in
                        zip(np.split(vector, [SIZES[0]]), SHAPES))
        with torch.inference_mode():
            expected1 = torch.nn.functional.conv2d(torch.from_numpy(frame)[None], conv1)[0].numpy()
            expected2 = torch.nn.functional.conv2d(torch.from_numpy(pooled)[None], conv2, stride=2)[0].numpy()
        got1, got2 = run_kernels(frame, vector, pooled)
        assert same_bits(got1, expected1) and same_bits(got2, expected2)


@pytest.mark.skipif(not torch_order_holds(), reason=NOT_HERE)
def test_the_default_features_are_torchs_path_on_car_racing_frames():
    """The default path is the ordered one here; its features equal torch's path's on 60 CarRacing frames
    and 10 random ones, for three weight scales, on two instances (the same bits twice)."""
    frames = car_racing_frames(60)
    rng = np.random.default_rng(12)
    frames += [rng.random((RGB, PIXEL_SIZE, PIXEL_SIZE), dtype=np.float32) for _ in range(10)]
    for scale in (1.0, 0.1, 10.0):
        vector = (rng.standard_normal(sum(SIZES)) * scale).astype(np.float32)
        first, second, reference = (ConvFeatures(vector, SHAPES), ConvFeatures(vector, SHAPES),
                                    ConvFeatures(vector, SHAPES, ordered=False))
        assert (first.path, reference.path) == ("ordered", "torch")
        for frame in frames:
            expected = reference(frame).copy()
            assert same_bits(first(frame), expected) and same_bits(second(frame), expected)
        assert same_bits(first(frames[3].astype(np.float64)), reference(frames[3]))  # any dtype, as torch's path


def test_the_check_refuses_another_order(monkeypatch):
    """Convolutions summed channel by channel, each product rounded before its sum (the compiled pass's
    order): the check says no, and the default is torch's path."""
    def channel_major(out, frame, weights):
        planes = frame[:RGB * PIXEL_SIZE * PIXEL_SIZE].reshape(RGB, PIXEL_SIZE, PIXEL_SIZE)
        sums = np.zeros((HIDDEN, SIZE1, SIZE1), np.float32)
        for o in range(HIDDEN):
            for c in range(RGB):
                for ky in range(3):
                    for kx in range(3):
                        sums[o] = sums[o] + weights[o, c, ky, kx] * planes[c, ky:ky + SIZE1, kx:kx + SIZE1]
        out[:sums.size] = sums.reshape(-1)

    monkeypatch.setattr(conv, "ordered_conv1", channel_major)
    assert torch_order_holds.__wrapped__() is False
    monkeypatch.setattr(conv, "torch_order_holds", lambda: False)
    vector = np.random.default_rng(13).standard_normal(sum(SIZES), dtype=np.float32)
    assert ConvFeatures(vector, SHAPES).path == "torch"


@pytest.mark.skipif(not torch_order_holds(), reason=NOT_HERE)
def test_the_check_accepts_the_kernels_here():
    assert torch_order_holds.__wrapped__() is True


def test_other_channel_counts_take_torchs_path():
    shapes = conv_shapes(4)
    vector = np.random.default_rng(14).standard_normal(sum(int(np.prod(s)) for s in shapes), dtype=np.float32)
    assert ConvFeatures(vector, shapes).path == "torch"
    assert ConvFeatures(vector, shapes, fast=True).path == "fast"
    with pytest.raises(ValueError, match="3-channel frames, not 4"):
        ConvFeatures(vector, shapes, ordered=True)


def test_the_columns_are_the_pooled_planes_split():
    pooled = np.random.default_rng(15).standard_normal((HIDDEN, POOLED1, POOLED1), dtype=np.float32)
    columns = np.zeros((HIDDEN, POOLED1, 2, COLUMNS), np.float32)
    split_columns(pooled, columns)
    assert same_bits(columns[:, :, 0, :21], pooled[:, :, 0::2])
    assert same_bits(columns[:, :, 1, :20], pooled[:, :, 1::2])


class TanhOf:
    """What ``_tanh_pools_first`` uses of torch, with ``tanh`` (float32 -> float32) as its tanh_."""

    def __init__(self, tanh):
        self.tanh = tanh

    def inference_mode(self):
        return torch.inference_mode()

    def from_numpy(self, values):
        tanh = self.tanh

        class Tensor:
            def tanh_(self):
                return Tensor()

            def numpy(self):
                return tanh(values)
        return Tensor()


def test_pooling_before_tanh_is_torchs_pooling_of_tanh_on_windows_of_near_values():
    """Windows of neighbouring floats, equal values, zeros of both signs, subnormals, saturation and NaNs:
    tanh_ of max_pool2 is max_pool2 of tanh_, bit for bit, as the ordered path relies on."""
    rng = np.random.default_rng(16)
    centres = np.concatenate([rng.standard_normal(3000) * 3, [0.0, -0.0, 1e-42, -1e-42, 9.0, -9.0, 12.0]])
    windows = []
    for centre in centres.astype(np.float32):  # four floats within 2 ulps of the centre, on its side of zero
        bits = np.maximum(np.abs(centre).view(np.int32) + rng.integers(-2, 3, size=4, dtype=np.int32), 0)
        windows.append(bits.view(np.float32) * (np.float32(-1) if np.signbit(centre) else np.float32(1)))
    planes = np.array(windows, dtype=np.float32).reshape(-1, 2, 2)
    planes[0] = [[-0.0, 0.0], [0.0, -0.0]]
    planes[1] = [[0.0, -0.0], [-1e-42, 1e-42]]
    planes[2] = [[np.nan, 1.0], [2.0, np.nan]]
    planes = np.ascontiguousarray(planes.transpose(1, 0, 2).reshape(1, 2, -1))  # window k: columns 2k, 2k + 1
    with torch.inference_mode():
        expected = max_pool2(torch.from_numpy(planes.copy()).tanh_().numpy())
        got = torch.from_numpy(max_pool2(planes)).tanh_().numpy()
    assert same_bits(got, expected)


def torch_tanh(x: np.ndarray) -> np.ndarray:
    return torch.from_numpy(x.astype(np.float32)).tanh_().numpy()


def rational_tanh(x: np.ndarray) -> np.ndarray:
    """The dense head's rational tanh (``policies.kernels``), in float32, term by term."""
    x = np.clip(x.astype(np.float32), -_TANH_CLAMP, _TANH_CLAMP)
    x2, p, q = x * x, np.float32(_TANH_P[0]), np.float32(_TANH_Q[0])
    for c in _TANH_P[1:]:
        p = p * x2 + np.float32(c)
    for c in _TANH_Q[1:]:
        q = q * x2 + np.float32(c)
    return x * p / q


def test_the_check_accepts_torchs_tanh_and_refuses_others():
    """Torch's tanh here passes. Refused: the dense head's rational tanh (a step down of one ulp at some
    floats), torch's with subnormals flushed to zero, torch's with the sign of zero lost."""
    if torch_order_holds():
        assert conv._tanh_pools_first(torch) and conv._tanh_pools_first(TanhOf(torch_tanh))
    tiny = np.finfo(np.float32).tiny
    for tanh in (rational_tanh, lambda x: np.where(np.abs(x) < tiny, np.float32(0), torch_tanh(x)),
                 lambda x: torch_tanh(x) + np.float32(0)):
        assert not conv._tanh_pools_first(TanhOf(tanh))


def test_a_tanh_the_pooling_cannot_go_before_means_torchs_path(monkeypatch):
    monkeypatch.setattr(conv, "_tanh_pools_first", lambda torch: False)
    assert torch_order_holds.__wrapped__() is False
