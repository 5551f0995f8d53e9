"""The pyBullet ant without the 40 zero-action steps after a reset: the policy acts from the first step, while
the ant drops from its start height. Everything else is the built-in recipe's (``envs.recipes.PYBULLET_ANT``)."""

from dataclasses import replace

from envs import register_recipe
from envs.recipes import PYBULLET_ANT

register_recipe(replace(PYBULLET_ANT, name="pyBullet ant, no burn-in", burn_in=0))
