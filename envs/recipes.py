"""Per-family environment behaviour of the original code, as data (docs/original.md, "Hebbian rules" and "Episodes").

The original chose behaviour with string tests on exact ids inside the episode loop
(``environment == 'CarRacing-v0'``, ``environment[-12:-6] == 'Bullet'``), so a renamed or custom
environment silently lost it. Here an environment's family is recognised once, when it is made,
from the class of the unwrapped environment, and its ``Recipe`` turns each quirk into a wrapper or
a network option:

    family        output   action                   early stop                       other
    CarRacing     raw      [tanh, sigmoid, sigmoid]  21st negative reward in a row    -
    pyBullet ant  tanh     clip (a no-op)            31st negative after step 200     40-step burn-in, progress reward
    pyBullet      tanh     clip (a no-op)            31st negative after step 200     -
    Atari         raw      argmax                    the environment's own            no-op starts, frame skip 4,
                                                                                      FIRE reset, frame stack
    anything else raw      clip (Box) / argmax       the environment's own            -

Hebbian weights are normalised after every update for every family except pyBullet.

Images are preprocessed for the network that will see them: ``default`` (the original's 84 x 84 RGB,
or Atari's stack of 4 grayscale frames) or ``pytorch-es`` (its 1 x 42 x 42 running-normalised frame,
``envs.pytorch_es``), as the policy's network asks (``policies.networks.NETWORKS``).

A recipe is a plug-in (``plugins``) of the registry ``RECIPES``, chosen by what it matches rather than by a
setting: the last one registered whose ``matches`` takes the environment is its recipe, so the built-in ones
are listed from the most general to the most specific, and a custom one, registered later, wins over them.
Custom families are added with ``register_recipe`` from an importable module. The module is
recorded (``custom_recipe_modules``, saved in config.json), and every process that builds the
environments (worker processes, Ray actors, a resumed run) imports it first, so the recipe reaches
all of them.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass

import gymnasium as gym
from gymnasium import spaces

from envs.atari import atari_pipeline, is_atari
from envs.pytorch_es import pytorch_es_frames
from envs.wrappers import (
    ArgmaxAction,
    BurnIn,
    CarRacingAction,
    ClipAction,
    NegativeRewardStop,
    OneHotObservation,
    PixelObservation,
    ProgressReward,
)
from plugins import Plugin, Registry


@dataclass(frozen=True)
class Recipe(Plugin):
    matches: Callable[[gym.Env], bool]  # called once, on the unwrapped environment
    squash_output: bool = False  # tanh is the network's output activation (the rule sees it)
    action: Callable[[gym.Env], gym.Env] | None = None  # None: clip a Box, argmax a Discrete
    burn_in: int = 0
    reward: Callable[[gym.Env], gym.Env] | None = None
    stop_patience: int | None = None  # stop after more than this many negative rewards in a row
    stop_check_after: int = 0
    normalise_hebbian: bool = True
    preprocess: Callable[[gym.Env, str], gym.Env] | None = None  # replaces observation_pipeline (Atari)

    def wrap(self, env: gym.Env, preprocessing: str = "default") -> gym.Env:
        """Observation pipeline (images as ``preprocessing`` asks), then the family's quirks, innermost first."""
        if preprocessing not in PREPROCESSING:
            raise ValueError(f"unknown image preprocessing {preprocessing!r}; valid: {', '.join(PREPROCESSING)}")
        env = (self.preprocess or observation_pipeline)(env, preprocessing)
        if self.burn_in:
            env = BurnIn(env, self.burn_in)
        if self.reward is not None:
            env = self.reward(env)
        if self.stop_patience is not None:
            env = NegativeRewardStop(env, self.stop_patience, self.stop_check_after)
        return (self.action or default_action)(env)


PREPROCESSING = ("default", "pytorch-es")


def observation_pipeline(env: gym.Env, preprocessing: str = "default") -> gym.Env:
    space = env.observation_space
    if isinstance(space, spaces.Discrete):
        return OneHotObservation(env)
    if isinstance(space, spaces.Box) and len(space.shape) == 3:
        return PixelObservation(env) if preprocessing == "default" else pytorch_es_frames(env)
    if isinstance(space, spaces.Box) and len(space.shape) == 1:
        return env
    raise ValueError(f"unsupported observation space {space}: expected a vector Box, an RGB image "
                     f"Box (H, W, 3) or Discrete")


def default_action(env: gym.Env) -> gym.Env:
    if isinstance(env.action_space, spaces.Box) and len(env.action_space.shape) == 1:
        return ClipAction(env)
    if isinstance(env.action_space, spaces.Discrete):
        return ArgmaxAction(env)
    raise ValueError(f"unsupported action space {env.action_space}: expected a 1-D Box or Discrete")


def _is_car_racing(env: gym.Env) -> bool:
    try:
        from gymnasium.envs.box2d.car_racing import CarRacing
    except ImportError:  # Box2D missing: then no CarRacing can have been made either
        return False
    return isinstance(env, CarRacing)


def _is_pybullet(env: gym.Env) -> bool:
    return any(cls.__module__.startswith("pybullet_envs_gymnasium") for cls in type(env).__mro__)


def is_pybullet_ant(env: gym.Env) -> bool:
    if not _is_pybullet(env):
        return False
    from pybullet_envs_gymnasium.gym_locomotion_envs import AntBulletEnv

    return isinstance(env, AntBulletEnv)


_PYBULLET = dict(squash_output=True, stop_patience=30, stop_check_after=201, normalise_hebbian=False)

CAR_RACING = Recipe("CarRacing", _is_car_racing, action=CarRacingAction, stop_patience=20)
PYBULLET_ANT = Recipe("pyBullet ant", is_pybullet_ant, burn_in=40, reward=ProgressReward, **_PYBULLET)
PYBULLET = Recipe("pyBullet", _is_pybullet, **_PYBULLET)
ATARI = Recipe("Atari", is_atari, preprocess=atari_pipeline)
GYMNASIUM = Recipe("Gymnasium", lambda env: True)

RECIPES: Registry[Recipe] = Registry(None, [GYMNASIUM, ATARI, PYBULLET, PYBULLET_ANT, CAR_RACING])
_CUSTOM_MODULES: list[str] = []  # the modules that registered recipes, in order


def register_recipe(recipe: Recipe) -> None:
    """Give a family of (custom) environments its own behaviour; newest registrations win (a recipe of the
    same name is replaced).

    Call it at the top level of an importable module (the one that defines ``recipe.matches``):
    that module is what worker processes import to get the recipe too.
    """
    module = recipe.matches.__module__
    if module == "__main__":
        raise ValueError(f"recipe {recipe.name!r} is defined in the script being run; define it in an importable "
                         "module so that worker processes can import it too")
    RECIPES.add(recipe, replace=True)
    if module not in _CUSTOM_MODULES:
        _CUSTOM_MODULES.append(module)


def custom_recipe_modules() -> tuple[str, ...]:
    """The modules whose import registers this process's custom recipes."""
    return tuple(_CUSTOM_MODULES)


def import_recipe_modules(modules: tuple[str, ...]) -> None:
    """Import modules recorded by ``custom_recipe_modules`` (in a worker, or a resumed run)."""
    for module in modules:
        try:
            importlib.import_module(module)
        except ImportError as error:
            raise ValueError(f"cannot import {module!r}, which registers an environment recipe of this run: "
                             f"{error}") from None


def recipe_for(env: gym.Env) -> Recipe:
    """The last registered recipe that matches ``env`` (``GYMNASIUM``, first, matches every one)."""
    unwrapped = env.unwrapped
    return next(recipe for recipe in reversed(RECIPES.values()) if recipe.matches(unwrapped))
