"""The convolutional front end for pixel observations (upstream spec §3.1).

conv C->6 (k3, s1) -> tanh -> max-pool 2 -> conv 6->8 (k5, s2) -> tanh -> max-pool 2 -> 648 features,
C the observation's channels (3 for the original's RGB frames).
Its weights are evolved and never plastic. Three implementations compute it from the same weights:

- torch's: single-threaded ``conv2d`` and ``tanh_``, with ``max_pool2`` between them. Its numbers
  are the ones every run has been trained and pinned with (``tests/test_pinned.py``). torch is
  imported only when it is built, so state-vector runs never pay for it.
- the default for RGB frames where it gives torch's bits (``torch_order_holds``, checked once per
  process): the same function with each convolution compiled (``ordered_conv1``, ``ordered_conv2``)
  and summed in the order of torch's own kernel, each pooled before torch's ``tanh_`` (below):
  about 4x faster than torch's path on one frame (0.21 against 0.85 ms here). Where the check fails
  (another CPU, whose oneDNN kernel sums in another order, or has no FMA, or a torch whose tanh
  is not non-decreasing), and for other channel counts, torch's path runs. The check costs about
  0.5 s, once per process.
- ``--fast_conv`` (``fast_features``): one compiled pass over preallocated buffers, about 4x faster than
  torch's path on one frame (docs/speed-carracing.md). It differs from torch in the low bits (features
  within about 1e-5): its own summation order, and the dense head's rational tanh
  (``policies.kernels``) evaluated without fastmath (within 4.1e-7 of tanh over every float32), so it
  is opt-in.

The max-pooling is ``max_pool2``, a compiled loop that returns what torch's ``max_pool2d(x, 2)``
returns, bit for bit: on this 2-core machine torch's kernel took about 0.3 ms for the first
pooling, the loop 0.02 ms, and a forward pass went from about 1.1 to 0.75 ms (issue 9: with the
fast CarRacing, the pixel policy had become a third of a step).

Torch's order. For these shapes torch's ``conv2d`` runs oneDNN's direct convolution (``jit:avx2`` on
this machine), which starts each output at +0 and adds the window's taps row by row, column by
column, channel by channel, each with one fused multiply-add (``fma``: one rounding). The ordered
kernels do the same, each output row in passes (one per row of the window for conv1, one per
tap for conv2) whose partial sums go through memory exactly: a loop over a row's pixels with a
few taps in it vectorises, one with all 150 of conv2's does not. conv2's stride-2 taps read the
pooled planes split into even and odd columns, so that they too are contiguous. Rows are computed
whole vectors wide (88 of 82 pixels, 24 of 19), into planes whose rows are that wide (the pooling
reads the pixels used); the input buffers end in ``SLACK`` spare floats, which the last row's
taps read past its end. Each pass computes the same row of several output planes (three for conv1,
two for conv2), each input value loaded once for all of them: an output's multiply-adds depend
each on the one before, and sums for other planes are work the CPU does while it waits (conv1 0.77x
and conv2 0.65x the time of one plane per pass). (Where two NaNs with different payloads meet in
one multiply-add, which payload comes out may differ from torch's; a NaN stays a NaN.)

Pooling before tanh. A window's ``max_pool2`` of the tanh is the tanh of its ``max_pool2`` wherever
torch's tanh is non-decreasing, is zero only at zero and keeps a zero's sign: the first of the
window's equal maxima is then the first of its equal tanhs, and a NaN stays the last NaN. So the
ordered path pools each convolution's sums and applies torch's ``tanh_`` to the pooled planes, a
quarter of the values (torch's tanh, MKL's ``vsTanh``, had been most of the path's time). MKL's
kernel on this machine was checked over every float32 (``benchmarks/fast_conv.py --tanh_every 1``):
non-decreasing, odd, the identity on subnormals, NaN for NaN. ``torch_order_holds`` checks those
properties on a dense sample in each process (``_tanh_pools_first``, 5.2 million floats): it
refuses a kernel that steps down here and there, as a rational approximation does, but not one
that steps down only at a few floats outside the sample.

The compiled pass takes each window's maximum before its tanh: tanh is non-decreasing, so
tanh(max x) = max tanh(x), with a quarter of the tanh calls (the rational tanh steps down by one ulp
at some floats, so a feature may be 1 ulp from the max of the tanhs); conv2 computes only the 18 x 18 of its
19 x 19 outputs that the floor-mode pooling keeps. Per output pixel it sums, channel by channel,
the k x k taps in row-major order; the taps' loops have constant bounds (``K1``, ``K2``), so they
unroll and the loop over a row's pixels vectorises without fastmath.
"""

from __future__ import annotations

import functools

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core.extending import intrinsic

from policies.kernels import _TANH_CLAMP, _TANH_P, _TANH_Q
from policies.network import PIXEL_SIZE, NetworkSpec, conv_shapes

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


def worker_modules(net: NetworkSpec, fast: bool) -> tuple[str, ...]:
    """What a network's ConvFeatures imports (``Policy.worker_modules``): torch, for a pixel network
    but with the compiled pass."""
    return ("torch",) if net.pixels and not fast else ()


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
P0, P1, P2, P3, P4, P5, P6 = _TANH_P
Q0, Q1, Q2, Q3 = _TANH_Q


@njit(inline="always", **_FAST)
def rational_tanh(x: np.float32) -> np.float32:
    """The dense head's tanh (``policies.kernels._tanh``: Eigen's rational form), evaluated as written
    (no fastmath); NaN stays NaN. Its largest error: docs/speed-carracing.md, tests/test_fast_conv.py."""
    x = _TANH_CLAMP if x > _TANH_CLAMP else x
    x = -_TANH_CLAMP if x < -_TANH_CLAMP else x
    x2 = x * x
    p = (((((P0 * x2 + P1) * x2 + P2) * x2 + P3) * x2 + P4) * x2 + P5) * x2 + P6
    q = ((Q0 * x2 + Q1) * x2 + Q2) * x2 + Q3
    return x * p / q


@njit(inline="always")
def _convolve(planes, source, weights, size, kernel_size, stride) -> None:
    """planes (out, size, size) = the valid convolution of source (in, H, W) with weights (out, in, k, k)
    at ``stride``, its first ``size`` rows and columns. Inlined with constant sizes (``fast_features``):
    fixed loop lengths let the inner loops unroll (conv2 took 211 us with them read from the arrays,
    75 us so)."""
    for out in range(planes.shape[0]):
        for y in range(size):
            row = planes[out, y]
            row[:] = 0.0
            for channel in range(source.shape[0]):
                kernel = weights[out, channel]
                for x in range(size):
                    total = row[x]
                    for ky in range(kernel_size):
                        for kx in range(kernel_size):
                            total += kernel[ky, kx] * source[channel, stride * y + ky, stride * x + kx]
                    row[x] = total


@njit(**_FAST)
def _tanh_of_pooled(planes: np.ndarray, pooled: np.ndarray) -> None:
    """pooled (C, H/2, W/2) = tanh of each 2 x 2 window's maximum (``max_pool2``'s rule)."""
    max_pool2(planes, pooled)
    flat = pooled.reshape(-1)
    for index in range(flat.size):  # a loop of its own, which vectorises
        flat[index] = rational_tanh(flat[index])


@njit(**_FAST)
def fast_features(obs, conv1, conv2, planes1, pooled1, planes2, features) -> np.ndarray:
    """The 648 features of obs (C, 84, 84) float32 into ``features``, through the buffers planes1 (6, 82, 82),
    pooled1 (6, 41, 41), planes2 (8, 18, 18); the weights conv1 (6, C, 3, 3) and conv2 (8, 6, 5, 5)."""
    _convolve(planes1, obs, conv1, SIZE1, K1, 1)  # (6, 82, 82)
    _tanh_of_pooled(planes1, pooled1)
    _convolve(planes2, pooled1, conv2, SIZE2, K2, STRIDE2)  # (8, 18, 18) of conv2's 19 x 19: what the pooling keeps
    _tanh_of_pooled(planes2, features.reshape(planes2.shape[0], SIZE2 // 2, SIZE2 // 2))
    return features

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
    torch's order: per output, from +0, ``fma`` over the window's rows, columns, channels."""
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
    (flat), with conv2 (8, 6, 5, 5), in torch's order."""
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


class ConvFeatures:
    """The 648 features of one observation (``__call__``): the same array, overwritten, at every call.

    ``fast``: the compiled pass (opt-in, its own bits). Otherwise torch's bits: through the ordered
    kernels for RGB frames where ``torch_order_holds()``, else through torch's convolutions;
    ``ordered`` forces one or the other (the check itself, tests, benchmarks). ``path`` says which runs:
    "fast", "ordered" or "torch".
    """

    def __init__(self, conv_weights: np.ndarray, shapes: tuple[tuple[int, ...], ...], fast: bool = False,
                 ordered: bool | None = None):
        first, second = shapes
        split = int(np.prod(first))
        weights = np.ascontiguousarray(conv_weights, dtype=np.float32)
        conv1, conv2 = weights[:split].reshape(first).copy(), weights[split:].reshape(second).copy()
        pooled1 = np.empty((first[0], POOLED1, POOLED1), np.float32)
        self._features = np.empty(second[0] * (SIZE2 // 2) ** 2, np.float32)
        pooled2 = self._features.reshape(second[0], SIZE2 // 2, SIZE2 // 2)  # conv2's 19 x 19 pools to 9 x 9
        if fast:
            self.path, self._forward = "fast", self._fast
            self._weights = conv1, conv2
            self._buffers = (np.empty((first[0], SIZE1, SIZE1), np.float32), pooled1,
                             np.empty((second[0], SIZE2, SIZE2), np.float32), self._features)
            return
        import torch

        torch.set_num_threads(1)
        if ordered is None:
            ordered = first[1] == RGB and torch_order_holds()
        if ordered:
            if first[1] != RGB:
                raise ValueError(f"the ordered kernels take {RGB}-channel frames, not {first[1]}")
            self.path, self._forward = "ordered", self._ordered
            self._weights = conv1, conv2
            self._frame = np.zeros(RGB * PIXEL_SIZE * PIXEL_SIZE + SLACK, np.float32)
            self._planes1 = np.zeros(HIDDEN * SIZE1 * WIDE1, np.float32)
            self._planes2 = np.zeros(OUTS2 * FULL2 * WIDE2, np.float32)
            self._tensors = torch.from_numpy(pooled1), torch.from_numpy(pooled2)  # what tanh_ overwrites
            self._inputs = self._frame[:-SLACK].reshape(RGB, PIXEL_SIZE, PIXEL_SIZE)
            self._columns = np.zeros((HIDDEN, POOLED1, 2, COLUMNS), np.float32)
            self._columns_flat = self._columns.reshape(-1)  # the same floats, as ordered_conv2 reads them
            # the planes with their whole rows: max_pool2 pools what the pooled shape keeps, the used pixels
            self._pooling = (self._planes1.reshape(HIDDEN, SIZE1, WIDE1), pooled1,
                             self._planes2.reshape(OUTS2, FULL2, WIDE2), pooled2)
            return
        self.path, self._forward = "torch", self._torch_forward
        self._torch = torch
        self._conv1 = torch.from_numpy(conv1)
        self._conv2 = torch.from_numpy(conv2)
        self._pooled1, self._pooled2 = pooled1, pooled2

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return self._forward(obs)

    def _fast(self, obs: np.ndarray) -> np.ndarray:
        return fast_features(np.ascontiguousarray(obs, dtype=np.float32), *self._weights, *self._buffers)

    def _torch_forward(self, obs: np.ndarray) -> np.ndarray:
        torch = self._torch
        conv2d = torch.nn.functional.conv2d
        with torch.inference_mode():
            x = torch.from_numpy(np.ascontiguousarray(obs, dtype=np.float32))[None]
            max_pool2(conv2d(x, self._conv1).tanh_()[0].numpy(), self._pooled1)
            max_pool2(conv2d(torch.from_numpy(self._pooled1)[None], self._conv2, stride=2).tanh_()[0].numpy(),
                      self._pooled2)
            return self._features

    def _ordered(self, obs: np.ndarray) -> np.ndarray:
        np.copyto(self._inputs, obs, casting="unsafe")  # np.ascontiguousarray(obs, dtype=np.float32)'s values
        (conv1, conv2), (tanh1, tanh2) = self._weights, self._tensors
        planes1, pooled1, planes2, pooled2 = self._pooling
        ordered_conv1(self._planes1, self._frame, conv1)
        max_pool2(planes1, pooled1)
        tanh1.tanh_()  # pooled, then tanh: torch's values (the module's docstring)
        split_columns(pooled1, self._columns)
        ordered_conv2(self._planes2, self._columns_flat, conv2)
        max_pool2(planes2, pooled2)
        tanh2.tanh_()
        return self._features


@functools.cache
def torch_order_holds() -> bool:
    """Whether the ordered kernels give torch's ``conv2d`` bits on this machine: checked once per process
    on random frames and weights, large weights, and a black frame under negative weights (the sign
    of a zero sum), each convolution's outputs and the features compared bit for bit. A different
    summation order, or multiply-adds rounded twice, changes the low bits of most outputs. And whether
    torch's tanh allows pooling before it (``_tanh_pools_first``)."""
    import torch

    if not _tanh_pools_first(torch):
        return False
    rng = np.random.default_rng(0)
    sizes = [int(np.prod(shape)) for shape in conv_shapes(RGB)]
    frames = [rng.random((RGB, PIXEL_SIZE, PIXEL_SIZE), dtype=np.float32) for _ in range(2)]
    frames.append(np.zeros((RGB, PIXEL_SIZE, PIXEL_SIZE), np.float32))
    weights = [rng.standard_normal(sum(sizes), dtype=np.float32) for _ in range(3)]
    weights[1], weights[2] = 30 * weights[1], -np.abs(weights[2])  # large sums; every product of a black pixel -0
    for frame, vector in zip(frames, weights):
        ordered = ConvFeatures(vector, conv_shapes(RGB), ordered=True)
        reference = ConvFeatures(vector, conv_shapes(RGB), ordered=False)
        if not _same_bits(ordered(frame), reference(frame)):
            return False
        (conv1, conv2), (planes1, pooled1, planes2, _) = ordered._weights, ordered._pooling
        ordered_conv1(ordered._planes1, ordered._frame, conv1)  # the raw sums, before tanh_
        ordered_conv2(ordered._planes2, ordered._columns_flat, conv2)  # from the pooled planes above
        with torch.inference_mode():
            sums1 = torch.nn.functional.conv2d(torch.from_numpy(frame)[None], torch.from_numpy(conv1))[0]
            sums2 = torch.nn.functional.conv2d(torch.from_numpy(pooled1)[None], torch.from_numpy(conv2), stride=2)[0]
        if not (_same_bits(planes1[:, :, :SIZE1], sums1.numpy()) and _same_bits(planes2[:, :, :FULL2], sums2.numpy())):
            return False
    return True


def tanh_faults(torch, magnitudes: np.ndarray) -> dict[str, int]:
    """What would keep pooling before torch's ``tanh_`` from giving torch's bits, counted over
    ``magnitudes`` (increasing non-negative float32) and their negatives: steps down from one float to
    the next, zeros away from zero, results of another sign than their input, and tanh(-x) not
    -tanh(x) bit for bit. All 0 on every float32: the tanh of a window's maximum is the maximum of
    its tanhs (the module's docstring)."""
    with torch.inference_mode():
        up = torch.from_numpy(magnitudes.copy()).tanh_().numpy()
        down = torch.from_numpy(-magnitudes).tanh_().numpy()
    return {"decreasing steps": int((np.diff(up) < 0).sum() + (np.diff(down) > 0).sum()),
            "zeros away from zero": int((((up == 0) | (down == 0)) & (magnitudes != 0)).sum()),
            "signs changed": int(np.signbit(up).sum() + (~np.signbit(down)).sum()),
            "not odd": int((down.view(np.uint32) != (-up).view(np.uint32)).sum())}


def _tanh_pools_first(torch, blocks: int = 40, run: int = 1 << 16) -> bool:
    """``tanh_faults`` none on a dense sample, NaN for NaN, +-1 for +-inf, and the same bits on a slice
    as on the whole. The sample: runs of ``run`` consecutive floats from ``blocks`` places between 0
    and 10 (past which tanh is 1 in float32), subnormals first, and their negatives; about 60 ms."""
    starts = np.linspace(0, np.float32(10.0).view(np.uint32), blocks).astype(np.uint32)
    magnitudes = (starts[:, None] + np.arange(run, dtype=np.uint32)).reshape(-1).view(np.float32)
    if any(tanh_faults(torch, magnitudes).values()):
        return False
    with torch.inference_mode():
        special = torch.from_numpy(np.float32([np.nan, np.inf, -np.inf])).tanh_().numpy()
        whole = torch.from_numpy(magnitudes.copy()).tanh_().numpy()
        part = torch.from_numpy(magnitudes[3:run].copy()).tanh_().numpy()
    return bool(np.isnan(special[0]) and np.array_equal(special[1:], [1, -1]) and _same_bits(part, whole[3:run]))


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and np.array_equal(a.view(np.uint32), b.view(np.uint32))
