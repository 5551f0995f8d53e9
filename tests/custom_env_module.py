"""A custom environment registered on import, for Gymnasium's ``module:EnvId`` form.

``--environment tests.custom_env_module:TestCorridor-v0`` imports this module, which registers
``TestCorridor-v0``: a walker on a line that is rewarded +1 for each step to the right and -1 for
each step to the left. It is deterministic and fast, so tests can train on it.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces

ENV_ID = "TestCorridor-v0"
MAX_STEPS = 20


class Corridor(gym.Env):
    """Observation: (position, steps taken) as floats; action: 0 = left, 1 = right."""

    metadata = {"render_modes": []}

    def __init__(self, render_mode: str | None = None):
        self.observation_space = spaces.Box(-np.inf, np.inf, (2,), dtype=np.float32)
        self.action_space = spaces.Discrete(2)
        self.render_mode = render_mode
        self._position = 0
        self._steps = 0

    def _observation(self) -> np.ndarray:
        return np.array([self._position, self._steps], dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self._position = 0
        self._steps = 0
        return self._observation(), {}

    def step(self, action):
        move = 1 if int(action) == 1 else -1
        self._position += move
        self._steps += 1
        return self._observation(), float(move), False, False, {}


if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point=Corridor, max_episode_steps=MAX_STEPS)

# The same environment under a namespaced id, as Gymnasium's ``ALE/Pong-v5``: a '/' in the id
NAMESPACED_ID = "Tests/Corridor-v0"
if NAMESPACED_ID not in gym.registry:
    gym.register(id=NAMESPACED_ID, entry_point=Corridor, max_episode_steps=MAX_STEPS)
