"""The quadruped's episode as the original ran it (``OriginalAnt``) and as this tool runs it (``ToolAnt``), stepped
alike (experiments/original_ant.py compares them).

The original code (Najarro & Risi 2020, ``fitness_functions.py``) stepped pyBullet's own ``pybullet_envs`` under the
old ``gym``: a fresh ``gym.make('AntBulletEnv-v0')`` for every episode, never seeded, 40 zero actions after the reset,
the progress term ``rewards[1]`` as the reward, and from policy step 202 on an end at ``done`` or at the 31st negative
reward in a row (docs/original.md, "Episodes"). The damaged bodies were, as its README says, the two MJCF files of
``damaged_bullet_morphologies/`` registered as gym environments. The pinned pyBullet wheel still ships those classes;
they need an old ``gym`` (the ``original`` extra: ``pip install -r requirements-original.txt``).
"""

from __future__ import annotations

import contextlib
import io
import warnings
from dataclasses import dataclass

import numpy as np

from envs import damaged, make_env, quiet_output

BODIES = ("AntBulletEnv-v0", "AntAsymRightBulletEnv-v0", "AntAsymLeftBulletEnv-v0")  # the paper's three
EXTRA = "the original extra (an old gym for pyBullet's pybullet_envs): pip install -r requirements-original.txt"
BURN_IN = 40  # zero actions after the reset (the original's "burnout phase")
CHECK_AFTER = 200  # the original tests its stop only where t > 200 (t counts policy steps from 0)
PATIENCE = 30  # ... and stops at done, or where more than 30 rewards in a row were negative
MAX_EPISODE_STEPS = 1000  # gym's TimeLimit of AntBulletEnv-v0, burn-in included


class OriginalUnavailable(RuntimeError):
    """``gym`` or what ``pybullet_envs`` imports with it is missing."""


def missing_modules() -> list[str]:
    """The modules of the original extra that cannot be imported here."""
    import importlib.util

    return [module for module in ("gym", "pkg_resources") if importlib.util.find_spec(module) is None]


@contextlib.contextmanager
def _quiet():
    """gym's notice on import (Python), pybullet_envs' warning that pkg_resources is deprecated, and pyBullet's banner
    (C), dropped."""
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()), quiet_output(), \
            warnings.catch_warnings():
        warnings.filterwarnings("ignore", "pkg_resources is deprecated", UserWarning)
        yield


def original_gym():
    """The old ``gym`` with ``pybullet_envs`` registered, and the damaged ants registered beside it."""
    missing = missing_modules()
    if missing:
        raise OriginalUnavailable(f"{', '.join(missing)} not installed; needs {EXTRA}")
    with _quiet():
        import gym
        import pybullet_envs  # noqa: F401  (registers AntBulletEnv-v0 with gym)
    for env_id in damaged.BULLET_IDS:
        if env_id not in gym.envs.registry.env_specs:
            # the README's way: each MJCF file a custom gym environment, the standard ant's TimeLimit kept
            gym.envs.registration.register(env_id, entry_point=_damaged_original, max_episode_steps=MAX_EPISODE_STEPS,
                                           kwargs={"side": damaged.BULLET_IDS[env_id]})
    return gym


def _damaged_original(side: str):
    """``pybullet_envs``'s ant, its robot loading a damaged MJCF file (an absolute path: pyBullet's
    ``os.path.join`` with its data folder keeps it as it is)."""
    from pybullet_envs.gym_locomotion_envs import AntBulletEnv

    env = AntBulletEnv()
    env.robot.model_xml = str(damaged.bullet_xml(side))
    return env


@dataclass
class Step:
    """What one policy step gives: the observation after it, the reward the original scores (the progress term), and
    whether the episode ends there."""
    observation: np.ndarray
    reward: float
    ends: bool


class OriginalAnt:
    """One environment id as the original's fitness function ran it: ``reset`` makes it afresh (the original's
    ``gym.make`` per episode), seeds it, resets it and runs the burn-in; ``step`` is one step of its inner loop."""

    def __init__(self, env_id: str):
        if env_id not in BODIES:
            raise ValueError(f"unknown quadruped {env_id!r}; valid: {', '.join(BODIES)}")
        self.env_id, self._gym, self.env = env_id, original_gym(), None
        self._t = self._negative = 0

    def reset(self, seed: int) -> np.ndarray:
        self.close()
        with _quiet():
            self.env = self._gym.make(self.env_id)
            self.env.seed(int(seed))
            observation = self.env.reset()
            for _ in range(BURN_IN):
                self.env.step(np.zeros(8))
        self._t = self._negative = 0
        return observation

    def step(self, action: np.ndarray) -> Step:
        observation, _, done, _ = self.env.step(action)
        reward = self.env.unwrapped.rewards[1]  # "Distance walked"
        ends = False
        if self._t > CHECK_AFTER:
            self._negative = self._negative + 1 if reward < 0.0 else 0
            ends = bool(done or self._negative > PATIENCE)
        self._t += 1
        return Step(observation, float(reward), ends)

    @property
    def unwrapped(self):
        return self.env.unwrapped

    def close(self) -> None:
        if self.env is not None:
            self.env.close()
            self.env = None


class ToolAnt:
    """One environment id as this tool runs it: made once by ``envs.make_env`` (the batched class, or pyBullet's port
    where ``stock``; the recipe's burn-in, progress reward and stop; the warm-up reset), reset with a seed."""

    def __init__(self, env_id: str, stock: bool = False):
        if env_id not in BODIES:
            raise ValueError(f"unknown quadruped {env_id!r}; valid: {', '.join(BODIES)}")
        self.env_id = env_id
        if not stock:
            self.env, _ = make_env(env_id)
        elif env_id in damaged.BULLET_IDS:  # the port's class with the damaged file, wrapped as make_env wraps
            from envs.recipes import recipe_for

            with quiet_output():
                import gymnasium

                env = gymnasium.wrappers.TimeLimit(damaged.damaged_bullet_ant_class(stock=True)(
                    str(damaged.bullet_xml(damaged.BULLET_IDS[env_id]))), MAX_EPISODE_STEPS)
                self.env = recipe_for(env).wrap(env)
                self.env.reset(seed=0)
        else:
            self.env, _ = make_env(env_id.replace("BulletEnv", "BulletStockEnv"))

    def reset(self, seed: int) -> np.ndarray:
        observation, _ = self.env.reset(seed=int(seed))
        return observation

    def step(self, action: np.ndarray) -> Step:
        observation, reward, terminated, truncated, _ = self.env.step(action)
        return Step(observation, float(reward), bool(terminated or truncated))

    @property
    def unwrapped(self):
        return self.env.unwrapped

    def close(self) -> None:
        self.env.close()
