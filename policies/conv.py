"""The convolutional front end for pixel observations (Najarro & Risi 2020, the original code's CNN).

conv C->6 (k3, s1) -> tanh -> max-pool 2 -> conv 6->8 (k5, s2) -> tanh -> max-pool 2 -> 648 features,
C the observation's channels (3 for the original's RGB frames). Its weights are evolved and never
plastic. The features are a function of the weights and the frame alone, computed in an order this
module fixes, so that they are the same bits on every machine (docs/reproducibility.md):

- each convolution output starts at +0 and adds the window's taps row by row, column by column,
  channel by channel, each with one fused multiply-add (``fma``: one rounding, IEEE 754's
  fusedMultiplyAdd, which every CPU computes alike; a CPU without the instruction gets libm's
  exact ``fmaf``). This is the order of oneDNN's direct convolution, which torch's ``conv2d`` runs
  on AVX2 machines for these shapes, so the sums there equal torch's bit for bit;
- each plane is max-pooled (``max_pool2``: torch's ``max_pool2d(x, 2)``, bit for bit), and then its
  tanh taken, ``policies.elementary.rational_tanh``, the tanh of every network of the project. Pooling
  before the tanh is the original's tanh-then-pool for an exact tanh, which is non-decreasing, at a
  quarter of the tanh calls.

Two implementations compute it. For RGB frames, ``ordered_conv1`` and ``ordered_conv2``: each output
row in passes (one per row of the window for conv1, one per tap for conv2) whose partial sums go
through memory exactly: a loop over a row's pixels with a few taps in it vectorises, one with all
150 of conv2's does not. conv2's stride-2 taps read the pooled planes split into even and odd
columns, so that they too are contiguous. Rows are computed whole vectors wide (88 of 82 pixels,
24 of 19), into planes whose rows are that wide (the pooling reads the pixels used); the input
buffers end in ``SLACK`` spare floats, which the last row's taps read past its end. Each pass
computes the same row of several output planes (three for conv1, two for conv2), each input value
loaded once for all of them: an output's multiply-adds depend each on the one before, and sums for
other planes are work the CPU does while it waits. For other channel counts (a stack of grey
frames), ``ordered_conv``: the same order, one tap of one channel at a time over a whole output
row. (Where two NaNs with different payloads meet in one multiply-add, which payload comes out may
differ from torch's; a NaN stays a NaN.)
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core.extending import intrinsic

from policies.elementary import tanh_in_place
from policies.network import PIXEL_SIZE, conv_shapes

RGB = 3  # the channels the ordered kernels are compiled for
(HIDDEN, _, K1, _), (OUTS2, _, K2, _) = conv_shapes(RGB)  # conv1's 6 outputs (conv2's inputs), 3x3; conv2's 8, 5x5
STRIDE2 = 2
SIZE1 = PIXEL_SIZE - K1 + 1  # 82: conv1's output
POOLED1 = SIZE1 // 2  # 41
FULL2 = (POOLED1 - K2) // STRIDE2 + 1  # 19: conv2's output
SIZE2 = FULL2 // 2 * 2  # 18 of conv2's 19: the rows and columns its pooling keeps
WIDE1, WIDE2 = 88, 24  # the ordered kernels' rows, whole vectors of 8 floats: 82 and 19 pixels used
COLUMNS = 32  # the width of each half (even, odd columns) of the split pooled planes: 21 and 20 used
SLACK = 8  # spare floats after each flat input buffer of the ordered path (a row's taps read 6 past its end)
TOGETHER1, TOGETHER2 = 3, 2  # output planes per pass of ordered_conv1 and ordered_conv2 (as many sums
# as _conv1_rows and _conv2_rows write out)
if HIDDEN % TOGETHER1 or OUTS2 % TOGETHER2:
    raise ValueError(f"the ordered kernels compute {TOGETHER1} and {TOGETHER2} planes at a time, not a part of "
                     f"{HIDDEN} and {OUTS2}")


@njit(cache=True, nogil=True)  # no fastmath: NaN and the sign of zero must survive as they are
def max_pool2(planes: np.ndarray, pooled=None) -> np.ndarray:
    """``torch.nn.functional.max_pool2d(x, 2)`` of (C, H, W) float32 planes, bit for bit, into ``pooled``
    (C, H // 2, W // 2), a buffer of the caller's, or a new array. A smaller ``pooled`` pools the planes'
    first rows and columns (the ordered kernels' planes, whose rows are longer than the pixels used).

    PyTorch's CPU kernel (``aten/src/ATen/native/cpu/MaxPoolKernel.cpp``) scans each 2 x 2 window
    in row-major order from -inf and keeps a value if ``value > kept || isnan(value)``: the first of
    equal maxima (which decides the sign of a zero) and the last NaN win. The last row and column
    of an odd size are dropped (floor mode).
    """
    if pooled is None:
        channels, height, width = planes.shape
        pooled = np.empty((channels, height // 2, width // 2), dtype=np.float32)
    for channel in range(pooled.shape[0]):
        for row in range(pooled.shape[1]):
            top, bottom, kept = planes[channel, 2 * row], planes[channel, 2 * row + 1], pooled[channel, row]
            for column in range(pooled.shape[2]):
                largest = np.float32(-np.inf)
                for value in (top[2 * column], top[2 * column + 1], bottom[2 * column], bottom[2 * column + 1]):
                    if value > largest or np.isnan(value):
                        largest = value
                kept[column] = largest
    return pooled


@intrinsic
def fma(typingctx, a, b, c):
    """``a * b + c`` in float32, rounded once: LLVM's ``llvm.fma``, the CPU's FMA instruction (a call to
    libm's ``fmaf`` on a CPU without one)."""
    if not (a == b == c == types.float32):
        return None

    def codegen(context, builder, signature, args):
        kind = args[0].type
        function = builder.module.declare_intrinsic("llvm.fma", [kind], ir.FunctionType(kind, [kind] * 3))
        return builder.call(function, args)

    return types.float32(types.float32, types.float32, types.float32), codegen


_FAST = dict(cache=True, nogil=True, error_model="numpy")  # numpy's: a division without Python's zero check


@njit(inline="always")
def _conv1_rows(out, frame, conv1, o, y, ky, first):
    """Adds the window's row ``ky`` to row y of conv1's output planes o, o + 1, o + 2 (from +0 when ``first``)."""
    at, second, third = (o * SIZE1 + y) * WIDE1, ((o + 1) * SIZE1 + y) * WIDE1, ((o + 2) * SIZE1 + y) * WIDE1
    for x in range(WIDE1):
        total = np.float32(0.0) if first else out[at + x]
        total2 = np.float32(0.0) if first else out[second + x]
        total3 = np.float32(0.0) if first else out[third + x]
        for kx in range(K1):
            for c in range(RGB):
                value = frame[(c * PIXEL_SIZE + y + ky) * PIXEL_SIZE + kx + x]
                total = fma(conv1[o, c, ky, kx], value, total)
                total2 = fma(conv1[o + 1, c, ky, kx], value, total2)
                total3 = fma(conv1[o + 2, c, ky, kx], value, total3)
        out[at + x], out[second + x], out[third + x] = total, total2, total3


@njit(**_FAST)
def ordered_conv1(out, frame, conv1) -> None:
    """out (6 x 82 x WIDE1, flat) = conv1 of frame (3 x 84 x 84 + SLACK, flat) with conv1 (6, 3, 3, 3), in
    the module's order: per output, from +0, ``fma`` over the window's rows, columns, channels."""
    for o in range(0, HIDDEN, TOGETHER1):
        for y in range(SIZE1):
            for ky in range(K1):
                _conv1_rows(out, frame, conv1, o, y, ky, ky == 0)


@njit(inline="always")
def _conv2_rows(out, columns, conv2, o, y, ky, kx, first):
    """Adds tap (ky, kx) of every channel to row y of conv2's output planes o, o + 1 (from +0 when ``first``)."""
    at, second = (o * FULL2 + y) * WIDE2, ((o + 1) * FULL2 + y) * WIDE2
    for x in range(WIDE2):
        total = np.float32(0.0) if first else out[at + x]
        total2 = np.float32(0.0) if first else out[second + x]
        for c in range(HIDDEN):
            value = columns[((c * POOLED1 + STRIDE2 * y + ky) * 2 + kx % 2) * COLUMNS + kx // 2 + x]
            total = fma(conv2[o, c, ky, kx], value, total)
            total2 = fma(conv2[o + 1, c, ky, kx], value, total2)
        out[at + x], out[second + x] = total, total2


@njit(**_FAST)
def ordered_conv2(out, columns, conv2) -> None:
    """out (8 x 19 x WIDE2, flat) = conv2 (stride 2) of the pooled planes split by ``split_columns``
    (flat), with conv2 (8, 6, 5, 5), in the module's order."""
    for o in range(0, OUTS2, TOGETHER2):
        for y in range(FULL2):
            for ky in range(K2):
                for kx in range(K2):
                    _conv2_rows(out, columns, conv2, o, y, ky, kx, ky == 0 and kx == 0)


@njit(**_FAST)
def split_columns(pooled, columns) -> None:
    """The pooled planes' columns j into columns[c, row, j % 2, j // 2] (6, 41, 2, COLUMNS): conv2's stride-2
    taps, contiguous."""
    for c in range(pooled.shape[0]):
        for row in range(pooled.shape[1]):
            line, even, odd = pooled[c, row], columns[c, row, 0], columns[c, row, 1]
            for j in range((line.size + 1) // 2):
                even[j] = line[2 * j]
            for j in range(line.size // 2):
                odd[j] = line[2 * j + 1]


@njit(**_FAST)
def ordered_conv(out, phases, weights) -> None:
    """out (O, H', W') = the valid convolution, at stride s, of the planes (C, H, W) that ``phases`` (C, H, s,
    ceil(W / s)) holds split by column phase (``phases[c, y, p, j]`` = column s j + p: ``split_phases``),
    with weights (O, C, k, k), in the order of ``ordered_conv1``: per output, from +0, ``fma`` over the
    window's rows, columns, channels. Any channel count; each tap of each channel goes over a whole
    output row, reading consecutive floats (a loop that vectorises)."""
    outs, channels, size, _ = weights.shape
    _, height, stride, width = phases.shape
    rows, columns = out.shape[1], out.shape[2]
    flat_out, flat_phases = out.reshape(-1), phases.reshape(-1)
    flat_out[:] = 0.0
    for o in range(outs):
        for y in range(rows):
            at = np.uint64((o * rows + y) * columns)  # unsigned: no negative-index wrap, which keeps
            for ky in range(size):  # the row's loop from vectorising
                for kx in range(size):
                    for c in range(channels):
                        weight = weights[o, c, ky, kx]
                        start = np.uint64((((c * height + stride * y + ky) * stride) + kx % stride) * width
                                          + kx // stride)
                        for x in range(np.uint64(columns)):
                            flat_out[at + x] = fma(weight, flat_phases[start + x], flat_out[at + x])


@njit(**_FAST)
def split_phases(planes, phases) -> None:
    """``phases[c, y, p, j]`` = ``planes[c, y, s j + p]`` for the s phases of ``phases`` (C, H, s, ceil(W / s))."""
    stride = phases.shape[2]
    for c in range(planes.shape[0]):
        for y in range(planes.shape[1]):
            for x in range(planes.shape[2]):
                phases[c, y, x % stride, x // stride] = planes[c, y, x]


class ConvFeatures:
    """The 648 features of one observation (``__call__``): the same array, overwritten, at every call.

    Through the RGB kernels for RGB frames, through ``ordered_conv`` for other channel counts, or where
    ``specialised`` is False (tests, benchmarks): the same bits either way. ``path`` says which runs:
    "ordered" (the RGB kernels) or "general".
    """

    def __init__(self, conv_weights: np.ndarray, shapes: tuple[tuple[int, ...], ...], specialised: bool = True):
        first, second = shapes
        split = int(np.prod(first))
        weights = np.ascontiguousarray(conv_weights, dtype=np.float32)
        self._weights = weights[:split].reshape(first).copy(), weights[split:].reshape(second).copy()
        pooled1 = np.empty((first[0], POOLED1, POOLED1), np.float32)
        self._features = np.empty(second[0] * (SIZE2 // 2) ** 2, np.float32)
        pooled2 = self._features.reshape(second[0], SIZE2 // 2, SIZE2 // 2)  # conv2's 19 x 19 pools to 9 x 9
        if specialised and first[1] == RGB:
            self.path, self._forward = "ordered", self._ordered
            self._frame = np.zeros(RGB * PIXEL_SIZE * PIXEL_SIZE + SLACK, np.float32)
            self._planes1 = np.zeros(HIDDEN * SIZE1 * WIDE1, np.float32)
            self._planes2 = np.zeros(OUTS2 * FULL2 * WIDE2, np.float32)
            self._inputs = self._frame[:-SLACK].reshape(RGB, PIXEL_SIZE, PIXEL_SIZE)
            self._columns = np.zeros((HIDDEN, POOLED1, 2, COLUMNS), np.float32)
            self._columns_flat = self._columns.reshape(-1)  # the same floats, as ordered_conv2 reads them
            # the planes with their whole rows: max_pool2 pools what the pooled shape keeps, the used pixels
            self._pooling = (self._planes1.reshape(HIDDEN, SIZE1, WIDE1), pooled1,
                             self._planes2.reshape(OUTS2, FULL2, WIDE2), pooled2)
        else:
            self.path, self._forward = "general", self._general
            self._inputs = np.empty((first[1], PIXEL_SIZE, 1, PIXEL_SIZE), np.float32)  # stride 1: one phase
            self._phases = np.zeros((first[0], POOLED1, STRIDE2, (POOLED1 + 1) // 2), np.float32)
            self._pooling = (np.empty((first[0], SIZE1, SIZE1), np.float32), pooled1,
                             np.empty((second[0], FULL2, FULL2), np.float32), pooled2)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return self._forward(obs)

    def _ordered(self, obs: np.ndarray) -> np.ndarray:
        np.copyto(self._inputs, obs, casting="unsafe")  # np.ascontiguousarray(obs, dtype=np.float32)'s values
        conv1, conv2 = self._weights
        planes1, pooled1, planes2, pooled2 = self._pooling
        ordered_conv1(self._planes1, self._frame, conv1)
        max_pool2(planes1, pooled1)
        tanh_in_place(pooled1)  # pooled, then tanh (the module's docstring)
        split_columns(pooled1, self._columns)
        ordered_conv2(self._planes2, self._columns_flat, conv2)
        max_pool2(planes2, pooled2)
        tanh_in_place(pooled2)
        return self._features

    def _general(self, obs: np.ndarray) -> np.ndarray:
        np.copyto(self._inputs[:, :, 0], obs, casting="unsafe")
        conv1, conv2 = self._weights
        planes1, pooled1, planes2, pooled2 = self._pooling
        ordered_conv(planes1, self._inputs, conv1)
        max_pool2(planes1, pooled1)
        tanh_in_place(pooled1)
        split_phases(pooled1, self._phases)
        ordered_conv(planes2, self._phases, conv2)
        max_pool2(planes2, pooled2)
        tanh_in_place(pooled2)
        return self._features
