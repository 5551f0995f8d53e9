"""The pyBullet ant without the 40 zero-action steps after a reset: the policy acts from the first step, while
the ant drops from its start height. Everything else is the built-in recipe's (``envs.recipes.PYBULLET_ANT``), and
it takes only the bodies registered here (``NoBurnInAntBulletEnv-v0``, ...)."""

from dataclasses import replace

from envs import register_recipe
from envs.recipes import PYBULLET_ANT
from experiments.static_ant import made_for, register_bodies

register_bodies("NoBurnIn", __name__)


def matches(env) -> bool:
    return made_for(env, __name__)


register_recipe(replace(PYBULLET_ANT, name="pyBullet ant, no burn-in", matches=matches, burn_in=0))
