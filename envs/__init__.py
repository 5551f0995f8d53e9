"""Environments: construction, per-family recipes, wrappers, damaged morphologies, the rollout.

Importing this package lets pygame run without a display (unless the user chose a video driver),
registers the pyBullet environments and the damaged ants with Gymnasium, makes ``CarRacing-v3``
the fast, pixel-identical ``envs.car_racing.FastCarRacing`` (Gymnasium's own class stays available as
``CarRacingStock-v3``), and pyBullet's four walkers their batched classes of ``envs.bullet_locomotion``,
with the same numbers (pyBullet's own stay available as ``*BulletStockEnv-v0``). MuJoCo's GL backend
is left alone: training never renders, and ``envs.headless`` chooses one when frames are asked for.
"""

import os

USER_VIDEO_DRIVER = os.environ.get("SDL_VIDEODRIVER")  # the user's choice, before the default below
if not os.environ.get("DISPLAY"):
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

import gymnasium as gym  # noqa: E402

from envs.make import EnvironmentError_, make_env, quiet_output, register_fast_car_racing, resolve_env_id  # noqa: E402
from envs.problem import Problem, ProblemSpec  # noqa: E402
from envs.recipes import Recipe, custom_recipe_modules, recipe_for, register_recipe  # noqa: E402
from envs.rollout import Episode, episode_rng, rollout  # noqa: E402
from envs.settings import EnvSettings  # noqa: E402

gym.logger.min_level = 40  # errors only, as the original (gym.logger.set_level(40))
with quiet_output():  # (importing pybullet prints its build banner from C)
    try:
        import pybullet_envs_gymnasium  # registers *BulletEnv-v0
    except ImportError:  # pyBullet is optional for users who only need Gymnasium/MuJoCo
        pybullet_envs_gymnasium = None
    if pybullet_envs_gymnasium is not None:
        from envs import bullet_locomotion

        bullet_locomotion.register()

import envs.damaged  # noqa: E402,F401  (registers the damaged ants of Najarro & Risi 2020)

register_fast_car_racing()

__all__ = ["EnvSettings", "EnvironmentError_", "Episode", "Problem", "ProblemSpec", "Recipe", "episode_rng",
           "custom_recipe_modules", "make_env", "quiet_output", "recipe_for", "register_recipe", "resolve_env_id",
           "rollout"]
