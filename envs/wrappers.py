"""One small Gymnasium wrapper per environment quirk (docs/original.md, "Episodes").

Each wrapper does one thing and validates its arguments; ``envs.recipes`` decides which ones an
environment family gets. Artificial cut-offs are reported as ``truncated``, never ``terminated``.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.wrappers import TimeLimit
from numba import njit

from envs.area_resize import AreaResize, takes_area_path


def _network_output_space(size: int) -> spaces.Box:
    return spaces.Box(-np.inf, np.inf, (size,), dtype=np.float32)


class CarRacingAction(gym.ActionWrapper):
    """Raw network output -> [tanh(steer), sigmoid(gas), sigmoid(brake)], as the original."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.action_space = _network_output_space(3)

    def action(self, output: np.ndarray) -> np.ndarray:
        steer, gas, brake = float(output[0]), float(output[1]), float(output[2])
        return np.array([math.tanh(steer), 1.0 / (1.0 + math.exp(-gas)), 1.0 / (1.0 + math.exp(-brake))],
                        dtype=np.float32)


@njit(cache=True, nogil=True)
def _clip(values, bounds, clipped):
    """``clipped`` = ``np.clip(values, low, high)`` as float64, ``bounds`` the rows low and high, bit for bit
    (NaN stays NaN), in a fifth of its time: the array is small and np.clip's Python wrapper costs more
    than the work. (The caller makes ``clipped``: numpy makes an array in fewer instructions than a
    compiled function's returned one is handed back to Python, and each array passed costs as many.)"""
    for index in range(values.shape[0]):
        value = np.float64(values[index])
        if value == value:  # not NaN
            value = value if value > bounds[0, index] else bounds[0, index]
            value = value if value < bounds[1, index] else bounds[1, index]
        clipped[index] = value


class ClipAction(gym.ActionWrapper):
    """Clip a network output to the bounds of a Box action space."""

    def __init__(self, env: gym.Env):
        if not isinstance(env.action_space, spaces.Box):
            raise TypeError(f"ClipAction needs a Box action space, got {env.action_space}")
        super().__init__(env)
        self._bounds = np.stack([env.action_space.low, env.action_space.high]).astype(np.float64)
        self.action_space = _network_output_space(env.action_space.shape[0])

    def action(self, output: np.ndarray) -> np.ndarray:
        clipped = np.empty(self._bounds.shape[1])  # a new array: the output buffer is reused
        _clip(output, self._bounds, clipped)
        return clipped

    def step(self, output: np.ndarray):
        """``ActionWrapper.step`` with ``action`` written out: a call fewer at every step."""
        clipped = np.empty(self._bounds.shape[1])
        _clip(output, self._bounds, clipped)
        return self.env.step(clipped)


class ArgmaxAction(gym.ActionWrapper):
    """A Discrete action from network logits: the index of the largest output."""

    def __init__(self, env: gym.Env):
        if not isinstance(env.action_space, spaces.Discrete):
            raise TypeError(f"ArgmaxAction needs a Discrete action space, got {env.action_space}")
        super().__init__(env)
        self._start = int(env.action_space.start)
        self.action_space = _network_output_space(int(env.action_space.n))

    def action(self, output: np.ndarray) -> int:
        return self._start + int(np.argmax(output))


class OneHotObservation(gym.ObservationWrapper):
    """A Discrete observation as a one-hot float32 vector."""

    def __init__(self, env: gym.Env):
        if not isinstance(env.observation_space, spaces.Discrete):
            raise TypeError(f"OneHotObservation needs a Discrete observation space, got {env.observation_space}")
        super().__init__(env)
        self._start = int(env.observation_space.start)
        self._eye = np.eye(int(env.observation_space.n), dtype=np.float32)
        self.observation_space = spaces.Box(0.0, 1.0, (int(env.observation_space.n),), dtype=np.float32)

    def observation(self, observation) -> np.ndarray:
        return self._eye[int(observation) - self._start]


class PixelObservation(gym.ObservationWrapper):
    """RGB frame -> 84x84 (cv2 INTER_AREA) -> float32 in [0, 1] -> swapaxes(0, 2).

    The original's ``np.swapaxes(obs, 0, 2)`` gives (C, W, H): the image is transposed. It is kept
    so that CNN weights evolved by the original code see what they were evolved on. A uint8 frame
    that OpenCV resizes through its area tables (CarRacing's 96 x 96) goes through ``AreaResize``,
    the same values with the tables made once; any other through ``cv2.resize``.
    """

    SIZE = 84

    def __init__(self, env: gym.Env):
        shape = env.observation_space.shape
        if shape is None or len(shape) != 3 or shape[2] != 3:
            raise ValueError(f"pixel observations must be RGB images (H, W, 3), got shape {shape}")
        super().__init__(env)
        import cv2

        self._cv2 = cv2
        self.observation_space = spaces.Box(0.0, 1.0, (3, self.SIZE, self.SIZE), dtype=np.float32)
        self._frame = np.empty((self.SIZE, self.SIZE, 3), dtype=np.uint8)  # cv2 resizes into it
        self._area: AreaResize | None = None  # for frames of shape self._area_shape, where it applies
        self._area_shape: tuple[int, ...] | None = None

    def observation(self, observation: np.ndarray) -> np.ndarray:
        """The same float32s as ``swapaxes(frame.astype(float32) / 255.0, 0, 2)``, made contiguous,
        with one conversion and no intermediate array (the result is new: callers may keep it)."""
        frame = self._frame
        if observation.dtype == np.uint8 and observation.ndim == 3 and observation.shape[2] == 3:
            if observation.shape != self._area_shape:
                self._area_shape = observation.shape
                self._area = (AreaResize(observation.shape, (self.SIZE, self.SIZE))
                              if takes_area_path(observation.shape[:2], (self.SIZE, self.SIZE)) else None)
            if self._area is not None:
                return self._area(observation)
            frame = self._cv2.resize(observation, (self.SIZE, self.SIZE), dst=frame, interpolation=self._cv2.INTER_AREA)
        else:  # another dtype resizes to its own
            frame = self._cv2.resize(observation, (self.SIZE, self.SIZE), interpolation=self._cv2.INTER_AREA)
        out = np.empty((3, self.SIZE, self.SIZE), dtype=np.float32)
        return np.divide(frame.transpose(2, 1, 0), np.float32(255.0), out=out, dtype=np.float32)


class BurnIn(gym.Wrapper):
    """After every reset, ``steps`` zero actions that are neither rewarded nor seen by the policy.

    The pyBullet ant starts in the air; the original let it settle for 40 steps. As in the
    original, the observation returned is the one from the reset itself (the burn-in steps'
    observations were discarded), and the burn-in steps count toward the TimeLimit.
    ``info["burn_in_steps"]`` reports them so that step counts stay honest.
    """

    def __init__(self, env: gym.Env, steps: int):
        if steps < 0:
            raise ValueError(f"burn-in steps must be >= 0, got {steps}")
        super().__init__(env)
        self._steps = steps
        self._zeros = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)

    def reset(self, **kwargs):
        observation, info = self.env.reset(**kwargs)
        for _ in range(self._steps):
            self.env.step(self._zeros)
        return observation, {**info, "burn_in_steps": self._steps}


class ProgressReward(gym.Wrapper):
    """Reward = pyBullet's progress term ``env.unwrapped.rewards[1]`` (~60.6 x metres walked)."""

    def step(self, action):
        observation, reward, terminated, truncated, info = self.env.step(action)
        return observation, float(self.env.unwrapped.rewards[1]), terminated, truncated, info


class NegativeRewardStop(gym.Wrapper):
    """Stop an episode after more than ``patience`` consecutive negative rewards.

    Steps before ``check_after`` (counted from 0 after each reset) are exempt: they neither count
    toward the streak nor can terminate the episode, which is how the original treated pyBullet
    walkers (they rest below the "alive" height right after the burn-in). The stop is a
    truncation: the environment did not end the episode, we did.
    """

    def __init__(self, env: gym.Env, patience: int, check_after: int = 0):
        if patience < 0 or check_after < 0:
            raise ValueError(f"patience and check_after must be >= 0, got {patience}, {check_after}")
        super().__init__(env)
        self._patience = patience
        self._check_after = check_after
        self._t = 0
        self._streak = 0

    def reset(self, **kwargs):
        self._t = 0
        self._streak = 0
        return self.env.reset(**kwargs)

    def step(self, action):
        observation, reward, terminated, truncated, info = self.env.step(action)
        t = self._t
        self._t = t + 1
        if t < self._check_after:
            return observation, reward, False, truncated, info
        self._streak = self._streak + 1 if reward < 0 else 0
        if self._streak > self._patience:
            truncated = True
        return observation, reward, terminated, truncated, info


class MaxEpisodeSteps(TimeLimit):
    """``--max_episode_steps``: end an episode, as ``truncated``, after this many policy steps.

    Gymnasium's ``TimeLimit``, under its own name so that a run's wrapper stack (config.json)
    tells it from the environment's registered limit. It is the outermost wrapper, so it counts
    the steps the policy takes: a burn-in (the pyBullet ant's 40 zero-action steps, run inside
    ``reset``) is not counted, while the environment's own limit, further in, still counts it. An
    ant episode therefore has at most min(N, 1000 - 40) policy steps. It caps; it never lengthens
    an episode past the environment's own limit, nor overrides a recipe's early stop.
    """
