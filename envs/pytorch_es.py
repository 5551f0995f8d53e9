"""pytorch-es's image preprocessing (atgambardella/pytorch-es ``envs.py``, docs/original.md, "pytorch-es").

pytorch-es (after ikostrikov/pytorch-a3c and universe-starter-agent) fed its conv-LSTM with:

- ``PytorchESFrame``: the 210 x 160 Atari screen cropped to rows 34:194 and columns :160 (the
  playing field, without the score), resized to 80 x 80 and then to 42 x 42 (cv2's default bilinear
  interpolation, twice: "essentially mipmapping"), averaged over the colour channels, scaled to
  [0, 1], as a (1, 42, 42) float32 image;
- ``RunningNormalisation``: the image minus a running mean, divided by a running standard deviation
  (+1e-8), both exponential averages (alpha 0.9999) of each frame's mean and std over all its
  pixels, bias-corrected by 1 - alpha^t.

pytorch-es ran every rollout in a freshly forked process, so its running statistics started from
zero at every episode. Here they are reset at every ``reset()``: per-episode state, so an episode's
observations do not depend on which episodes a worker ran before. The statistics are updated in
float64 and the frame normalised in float32, which is what numpy 1.x (pytorch-es's) computed.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces

ATARI_CROP = (slice(34, 34 + 160), slice(0, 160))  # rows, columns of the 210 x 160 screen
FRAME_SIZE = 42
ALPHA = 0.9999


class PytorchESFrame(gym.ObservationWrapper):
    """RGB frame -> [crop] -> 80x80 -> 42x42 -> mean over channels -> /255, shape (1, 42, 42)."""

    def __init__(self, env: gym.Env, crop: tuple[slice, slice] | None = None):
        shape = env.observation_space.shape
        if shape is None or len(shape) != 3 or shape[2] != 3:
            raise ValueError(f"pytorch-es's preprocessing needs RGB images (H, W, 3), got shape {shape}")
        super().__init__(env)
        import cv2

        self._cv2 = cv2
        self._crop = crop if crop is not None else (slice(None), slice(None))
        self.observation_space = spaces.Box(0.0, 1.0, (1, FRAME_SIZE, FRAME_SIZE), dtype=np.float32)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        cv2 = self._cv2
        frame = observation[self._crop]
        frame = cv2.resize(cv2.resize(frame, (80, 80)), (FRAME_SIZE, FRAME_SIZE))
        gray = frame.mean(axis=2).astype(np.float32)
        gray *= np.float32(1.0 / 255.0)
        return gray.reshape(1, FRAME_SIZE, FRAME_SIZE)


class RunningNormalisation(gym.ObservationWrapper):
    """(x - mean_t) / (std_t + 1e-8) with bias-corrected exponential averages of the frames' mean and
    std; the averages restart at every reset (per-episode state)."""

    def __init__(self, env: gym.Env, alpha: float = ALPHA):
        if not 0.0 < alpha < 1.0:
            raise ValueError(f"alpha must be in (0, 1), got {alpha}")
        super().__init__(env)
        self._alpha = alpha
        self.observation_space = spaces.Box(-np.inf, np.inf, env.observation_space.shape, dtype=np.float32)
        self._restart()

    def _restart(self) -> None:
        self._mean = 0.0
        self._std = 0.0
        self._count = 0

    def reset(self, **kwargs):
        self._restart()
        return super().reset(**kwargs)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        alpha = self._alpha
        self._count += 1
        self._mean = self._mean * alpha + float(observation.mean()) * (1.0 - alpha)
        self._std = self._std * alpha + float(observation.std()) * (1.0 - alpha)
        correction = 1.0 - alpha ** self._count
        mean, std = self._mean / correction, self._std / correction
        return (observation - np.float32(mean)) / np.float32(std + 1e-8)


def pytorch_es_frames(env: gym.Env, crop: tuple[slice, slice] | None = None) -> gym.Env:
    """pytorch-es's whole image pipeline: the 42 x 42 frame, then its running normalisation."""
    return RunningNormalisation(PytorchESFrame(env, crop))
