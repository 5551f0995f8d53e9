"""A training problem: the environments to evaluate on and the policy that acts in them.

``ProblemSpec`` is small and picklable: it crosses to each worker once, and the worker builds the
``Problem`` (environments made once and reused for every episode) from it.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym
from gymnasium import spaces

from envs.make import make_env
from envs.recipes import Recipe, import_recipe_modules
from envs.rollout import Episode, rollout
from policies import NetworkSpec, PolicySettings, kind_of, make_policy, preprocessing


@dataclass(frozen=True)
class ProblemSpec:
    env_ids: tuple[str, ...]  # resolved ids; fitness is the mean over all of them
    policy: PolicySettings = PolicySettings()
    recipe_modules: tuple[str, ...] = ()  # imported before the environments are made (custom recipes)
    max_episode_steps: int | None = None  # cap on an episode's policy steps (``envs.wrappers.MaxEpisodeSteps``)

    def build(self, render_mode: str | None = None) -> Problem:
        return Problem(self, render_mode)


def network_spec(env: gym.Env, recipe: Recipe) -> NetworkSpec:
    """The network an environment (already wrapped by its recipe) needs."""
    inner = env.unwrapped.action_space
    n_actions = inner.shape[0] if isinstance(inner, spaces.Box) else int(inner.n)
    return NetworkSpec(tuple(env.observation_space.shape), n_actions, recipe.squash_output)


def wrapper_stack(env: gym.Env) -> list[str]:
    """The classes an observation passes through, outermost first, down to the environment itself."""
    stack = [type(env).__name__]
    while isinstance(env, gym.Wrapper):
        env = env.env
        stack.append(type(env).__name__)
    return stack


class Problem:
    def __init__(self, spec: ProblemSpec, render_mode: str | None = None):
        self.spec = spec
        self.envs: list[gym.Env] = []
        self.recipes: list[Recipe] = []
        import_recipe_modules(spec.recipe_modules)
        for env_id in spec.env_ids:
            env, recipe = self._make(env_id, render_mode)
            self.envs.append(env)
            self.recipes.append(recipe)
        self.net = network_spec(self.envs[0], self.recipes[0])
        for env_id, env, recipe in zip(spec.env_ids, self.envs, self.recipes):
            self._check_compatible(env_id, network_spec(env, recipe), recipe)
        self.policy = make_policy(spec.policy, self.net, self.recipes[0].normalise_hebbian)

    def _make(self, env_id: str, render_mode: str | None = None) -> tuple[gym.Env, Recipe]:
        return make_env(env_id, render_mode, preprocessing(self.spec.policy), self.spec.max_episode_steps)

    def _check_compatible(self, env_id: str, net: NetworkSpec, recipe: Recipe) -> None:
        first = self.spec.env_ids[0]
        if net != self.net:
            self.close()
            raise ValueError(f"{env_id} needs network {net.obs_shape} -> {net.n_actions} (output tanh: "
                             f"{net.squash_out}) but {first} needs {self.net.obs_shape} -> "
                             f"{self.net.n_actions} (output tanh: {self.net.squash_out}); "
                             "environments used together must share observation and action sizes")
        if recipe.normalise_hebbian != self.recipes[0].normalise_hebbian and kind_of(self.spec.policy).plastic:
            self.close()
            raise ValueError(f"{env_id} and {first} disagree on Hebbian weight normalisation; "
                             "train them separately")

    def wrappers(self) -> dict[str, list[str]]:
        """Each environment's wrapper stack (recorded in config.json)."""
        return {env_id: wrapper_stack(env) for env_id, env in zip(self.spec.env_ids, self.envs)}

    def evaluate(self, params, env_index: int, seed: int, max_steps: int | None = None) -> Episode:
        return rollout(self.envs[env_index], self.policy, params, seed, max_steps=max_steps)

    def rebuild(self, env_index: int) -> None:
        """Replace an environment that raised by a fresh one."""
        try:
            self.envs[env_index].close()
        except Exception:  # the env is already broken; a failing close must not hide the retry
            pass
        self.envs[env_index], _ = self._make(self.spec.env_ids[env_index])

    def close(self) -> None:
        for env in self.envs:
            env.close()
