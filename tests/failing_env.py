"""A tiny environment that fails on purpose, for the fault-handling tests (tests/test_faults.py).

Use it as ``--environment tests.failing_env:FailingEnv-v0``. Importing this module registers the id.
It behaves like a 20-step episode with reward 1 per step, except at step ``FAILING_ENV_STEP``,
where it does what ``FAILING_ENV_HOW`` says:

    raise     raise RuntimeError("FailingEnv: failure at step k")
    exit      end the process with os._exit(3)            (only in a worker process)
    segfault  dereference a NULL pointer through ctypes    (only in a worker process)
    nan       return a NaN reward when the action is 1 (so only some members get NaN)
    hang      sleep HANG_SECONDS, as a stuck simulator would (for the Ctrl-C tests)
    nan_obs   return NaN observations from step k on (k = 0: from the reset on)

If ``FAILING_ENV_ONCE`` names a file, the failure happens only while that file does not exist, and
the first failure creates it: exactly one episode fails in the whole run, in whichever process, so
the retry succeeds. ``FAILING_ENV_AFTER`` episodes of each environment instance run normally before
any failure (default 0), so that a test can see an episode finish first. Settings are read from the
environment variables when the env is made.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import time

import gymnasium as gym
import numpy as np
from gymnasium import spaces

EPISODE_STEPS = 20
HOW = ("raise", "exit", "segfault", "nan", "hang", "nan_obs")
HANG_SECONDS = 600


class FailingEnv(gym.Env):
    """Observation: a 4-vector that depends on the step; action: 0 or 1; reward: 1 per step."""

    def __init__(self, step: int | None = None, how: str | None = None, once: str | None = None,
                 render_mode: str | None = None):
        self.render_mode = render_mode
        self.observation_space = spaces.Box(-1.0, 1.0, (4,), dtype=np.float32)
        self.action_space = spaces.Discrete(2)
        self.fail_step = int(step if step is not None else os.environ.get("FAILING_ENV_STEP", -1))
        self.how = how or os.environ.get("FAILING_ENV_HOW", "raise")
        if self.how not in HOW:
            raise ValueError(f"FAILING_ENV_HOW={self.how!r}; valid: {', '.join(HOW)}")
        self.once = once or os.environ.get("FAILING_ENV_ONCE") or None
        self.after = int(os.environ.get("FAILING_ENV_AFTER", 0))
        self._episodes = 0  # episodes that took a step (a reset alone, as a shape probe makes, is none)
        self._t = 0
        self._phase = 0.0

    def reset(self, *, seed: int | None = None, options=None):
        super().reset(seed=seed)
        self._t = 0
        self._phase = float(self.np_random.uniform(-1, 1))
        return self._observation(), {}

    def step(self, action):
        self._t += 1
        self._episodes += self._t == 1
        reward = 1.0
        if self._t == self.fail_step and self._episodes > self.after and self._should_fail():
            reward = self._fail(int(action))
        return self._observation(), reward, False, self._t >= EPISODE_STEPS, {}

    def _observation(self) -> np.ndarray:
        if self.how == "nan_obs" and self._t >= self.fail_step >= 0:
            return np.full(4, np.nan, dtype=np.float32)
        angles = self._phase + 0.3 * self._t * np.arange(1, 5)
        return np.sin(angles).astype(np.float32)

    def _should_fail(self) -> bool:
        if self.once is None:
            return True
        try:  # O_EXCL: only the first process to get here fails
            os.close(os.open(self.once, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        except FileExistsError:
            return False
        return True

    def _fail(self, action: int) -> float:
        in_worker = multiprocessing.parent_process() is not None
        if self.how == "raise":
            raise RuntimeError(f"FailingEnv: failure at step {self._t}")
        if self.how == "exit" and in_worker:
            os._exit(3)
        if self.how == "segfault" and in_worker:
            ctypes.string_at(0)  # reads address 0: SIGSEGV
        if self.how == "nan":
            return float("nan") if action == 1 else 1.0
        if self.how == "hang":
            time.sleep(HANG_SECONDS)
        return 1.0


gym.register("FailingEnv-v0", entry_point=FailingEnv)
