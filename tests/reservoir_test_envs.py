"""A custom environment whose episodes outlast a short PPO training (2048 steps), for the ER-MRL tests:
``--env_id tests.reservoir_test_envs:TestLongCorridor-v0`` finishes no episode, so the trial is pruned.
"""

import gymnasium as gym

from tests.custom_env_module import Corridor

ENV_ID = "TestLongCorridor-v0"

if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point=Corridor, max_episode_steps=5000)
