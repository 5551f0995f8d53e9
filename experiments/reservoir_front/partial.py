"""CartPole without its velocities: ``CartPoleNoVelocity-v1``, ER-MRL's ``--del_obs True`` task for this tool's scripts.

The agent sees the cart's position and the pole's angle only (observation indices 0 and 2 of CartPole-v1,
as ``reservoirs.wrappers.DeletedVelocityWrapper`` keeps them); dynamics, rewards and the 500-step limit
are CartPole-v1's. A feedforward network cannot tell which way the pole is moving; a network with memory
can. Import it through the environment id, so that workers and resumed runs import it too:

    python train_static.py --environment experiments.reservoir_front.partial:CartPoleNoVelocity-v1 --reservoir
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.envs.classic_control.cartpole import CartPoleEnv

ENV_ID = "CartPoleNoVelocity-v1"
KEEP = np.array([0, 2])  # cart position, pole angle


class CartPoleNoVelocity(CartPoleEnv):
    def __init__(self, render_mode: str | None = None):
        super().__init__(render_mode=render_mode)
        self.observation_space = spaces.Box(self.observation_space.low[KEEP], self.observation_space.high[KEEP],
                                            dtype=self.observation_space.dtype)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        observation, info = super().reset(seed=seed, options=options)
        return observation[KEEP], info

    def step(self, action):
        observation, reward, terminated, truncated, info = super().step(action)
        return observation[KEEP], reward, terminated, truncated, info


if ENV_ID not in gym.registry:
    gym.register(ENV_ID, entry_point=CartPoleNoVelocity, max_episode_steps=500, reward_threshold=475.0)
