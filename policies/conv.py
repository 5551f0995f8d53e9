"""The convolutional front end for pixel observations (upstream spec §3.1), in single-threaded torch.

conv C->6 (k3, s1) -> tanh -> max-pool 2 -> conv 6->8 (k5, s2) -> tanh -> max-pool 2 -> 648 features,
C the observation's channels (3 for the original's RGB frames).
Its weights are evolved and never plastic. torch is imported only when a pixel network is built,
so state-vector runs never pay for it.
"""

from __future__ import annotations

import numpy as np


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
        functional = torch.nn.functional
        with torch.inference_mode():
            x = torch.from_numpy(np.ascontiguousarray(obs, dtype=np.float32))[None]
            x = functional.max_pool2d(torch.tanh(functional.conv2d(x, self._conv1)), 2)
            x = functional.max_pool2d(torch.tanh(functional.conv2d(x, self._conv2, stride=2)), 2)
            return x.reshape(-1).numpy()
