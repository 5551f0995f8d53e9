"""The pyBullet ant without the first 201 steps' grace: the environment's end of an episode (the torso at or
below 0.26 m) and the run of 31 negative rewards count from the first policy step, not from the 202nd.
Everything else is the built-in recipe's (``envs.recipes.PYBULLET_ANT``), the burn-in included, and it takes only
the bodies registered here (``NoGraceAntBulletEnv-v0``, ...)."""

from dataclasses import replace

from envs import register_recipe
from envs.recipes import PYBULLET_ANT
from experiments.static_ant import made_for, register_bodies

register_bodies("NoGrace", __name__)


def matches(env) -> bool:
    return made_for(env, __name__)


register_recipe(replace(PYBULLET_ANT, name="pyBullet ant, no grace", matches=matches, stop_check_after=0))
