"""The convolutional front end for pixel observations (upstream spec §3.1).

conv C->6 (k3, s1) -> tanh -> max-pool 2 -> conv 6->8 (k5, s2) -> tanh -> max-pool 2 -> 648 features,
C the observation's channels (3 for the original's RGB frames).
Its weights are evolved and never plastic. Two implementations compute it from the same weights:

- the default, single-threaded torch (``conv2d``, ``tanh_``) with ``max_pool2`` between them: the numbers
  every run has been trained and pinned with (``tests/test_pinned.py``). torch is imported only when it
  is built, so state-vector runs never pay for it.
- ``--fast_conv`` (``fast_features``): one compiled pass over preallocated buffers, about 4x faster on
  one frame (docs/speed-carracing.md). It differs from torch in the low bits (features within about
  1e-5): its own summation order, and the dense head's rational tanh (``policies.kernels``) evaluated
  without fastmath (within 4.1e-7 of tanh over every float32), so it is opt-in.

The max-pooling is ``max_pool2``, a compiled loop that returns what torch's ``max_pool2d(x, 2)``
returns, bit for bit: on this 2-core machine torch's kernel took about 0.3 ms for the first
pooling, the loop 0.02 ms, and a forward pass went from about 1.1 to 0.75 ms (issue 9: with the
fast CarRacing, the pixel policy had become a third of a step).

The compiled pass takes each window's maximum before its tanh: tanh is non-decreasing, so
tanh(max x) = max tanh(x), with a quarter of the tanh calls (the rational tanh steps down by one ulp
at some floats, so a feature may be 1 ulp from the max of the tanhs); conv2 computes only the 18 x 18 of its
19 x 19 outputs that the floor-mode pooling keeps. Per output pixel it sums, channel by channel,
the k x k taps in row-major order; the taps' loops have constant bounds (``K1``, ``K2``), so they
unroll and the loop over a row's pixels vectorises without fastmath.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from policies.kernels import _TANH_CLAMP, _TANH_P, _TANH_Q
from policies.network import PIXEL_SIZE, NetworkSpec

K1, K2 = 3, 5  # the kernel sizes of policies.network.conv_shapes
STRIDE2 = 2
SIZE1 = PIXEL_SIZE - K1 + 1  # 82: conv1's output
SIZE2 = ((SIZE1 // 2 - K2) // STRIDE2 + 1) // 2 * 2  # 18 of conv2's 19: the rows and columns its pooling keeps


def worker_modules(net: NetworkSpec, fast: bool) -> tuple[str, ...]:
    """What a network's ConvFeatures imports (``Policy.worker_modules``): torch, for a pixel network
    but with the compiled pass."""
    return ("torch",) if net.pixels and not fast else ()


@njit(cache=True, nogil=True)  # no fastmath: NaN and the sign of zero must survive as they are
def max_pool2(planes: np.ndarray, pooled=None) -> np.ndarray:
    """``torch.nn.functional.max_pool2d(x, 2)`` of (C, H, W) float32 planes, bit for bit, into ``pooled``
    (C, H // 2, W // 2), a buffer of the caller's, or a new array.

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


class ConvFeatures:
    """The 648 features of one observation (``__call__``): the same array, overwritten, at every call.
    ``fast``: the compiled pass; otherwise torch's convolutions and tanh, pooled (``max_pool2``) into
    buffers of its own."""

    def __init__(self, conv_weights: np.ndarray, shapes: tuple[tuple[int, ...], ...], fast: bool = False):
        first, second = shapes
        split = int(np.prod(first))
        weights = np.ascontiguousarray(conv_weights, dtype=np.float32)
        conv1, conv2 = weights[:split].reshape(first).copy(), weights[split:].reshape(second).copy()
        self._forward = self._fast if fast else self._torch_forward
        pooled1 = np.empty((first[0], SIZE1 // 2, SIZE1 // 2), np.float32)
        features = np.empty(second[0] * (SIZE2 // 2) ** 2, np.float32)
        if fast:
            self._weights = conv1, conv2
            self._buffers = (np.empty((first[0], SIZE1, SIZE1), np.float32), pooled1,
                             np.empty((second[0], SIZE2, SIZE2), np.float32), features)
            return
        import torch

        torch.set_num_threads(1)
        self._torch = torch
        self._conv1 = torch.from_numpy(conv1)
        self._conv2 = torch.from_numpy(conv2)
        self._pooled1, self._features = pooled1, features
        self._pooled2 = features.reshape(second[0], SIZE2 // 2, SIZE2 // 2)  # conv2's 19 x 19 pools to 9 x 9

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
