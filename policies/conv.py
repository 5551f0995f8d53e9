"""The convolutional front end for pixel observations (upstream spec §3.1), in single-threaded torch.

conv C->6 (k3, s1) -> tanh -> max-pool 2 -> conv 6->8 (k5, s2) -> tanh -> max-pool 2 -> 648 features,
C the observation's channels (3 for the original's RGB frames).
Its weights are evolved and never plastic. torch is imported only when a pixel network is built,
so state-vector runs never pay for it.

The max-pooling is ``max_pool2``, a compiled loop that returns what torch's ``max_pool2d(x, 2)``
returns, bit for bit: on this 2-core machine torch's kernel took about 0.3 ms for the first
pooling, the loop 0.02 ms, and a forward pass went from about 1.1 to 0.75 ms (issue 9: with the
fast CarRacing, the pixel policy had become a third of a step).
"""

from __future__ import annotations

import numpy as np
from numba import njit

MODULES = ("torch",)  # what ConvFeatures imports (a policy with a front end names them: worker_modules)


@njit(cache=True, nogil=True)  # no fastmath: NaN and the sign of zero must survive as they are
def max_pool2(planes: np.ndarray) -> np.ndarray:
    """``torch.nn.functional.max_pool2d(x, 2)`` of (C, H, W) float32 planes, bit for bit.

    PyTorch's CPU kernel (``aten/src/ATen/native/cpu/MaxPoolKernel.cpp``) scans each 2 x 2 window
    in row-major order from -inf and keeps a value if ``value > kept || isnan(value)``: the first of
    equal maxima (which decides the sign of a zero) and the last NaN win. The last row and column
    of an odd size are dropped (floor mode).
    """
    channels, height, width = planes.shape
    pooled = np.empty((channels, height // 2, width // 2), dtype=np.float32)
    for channel in range(channels):
        for row in range(height // 2):
            for column in range(width // 2):
                kept = np.float32(-np.inf)
                for dy in range(2):
                    for dx in range(2):
                        value = planes[channel, 2 * row + dy, 2 * column + dx]
                        if value > kept or np.isnan(value):
                            kept = value
                pooled[channel, row, column] = kept
    return pooled


class ConvFeatures:
    def __init__(self, conv_weights: np.ndarray, shapes: tuple[tuple[int, ...], ...]):
        import torch

        torch.set_num_threads(1)
        first, second = shapes
        split = int(np.prod(first))
        weights = np.ascontiguousarray(conv_weights, dtype=np.float32)
        self._torch = torch
        self._conv1 = torch.from_numpy(weights[:split].reshape(first).copy())
        self._conv2 = torch.from_numpy(weights[split:].reshape(second).copy())

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        torch = self._torch
        conv2d = torch.nn.functional.conv2d
        with torch.inference_mode():
            x = torch.from_numpy(np.ascontiguousarray(obs, dtype=np.float32))[None]
            x = torch.from_numpy(max_pool2(conv2d(x, self._conv1).tanh_()[0].numpy()))[None]
            return max_pool2(conv2d(x, self._conv2, stride=2).tanh_()[0].numpy()).reshape(-1)
