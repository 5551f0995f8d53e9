"""A training problem: the environments to evaluate on and the policy that acts in them.

``ProblemSpec`` is small and picklable: it crosses to each worker once, and the worker builds the
``Problem`` (environments made once and reused for every episode) from it.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym
from gymnasium import spaces

from envs.make import make_env
from envs.recipes import Recipe
from envs.rollout import Episode, rollout
from policies import HebbianPolicy, NetworkSpec, StaticPolicy


@dataclass(frozen=True)
class ProblemSpec:
    env_ids: tuple[str, ...]  # resolved ids; fitness is the mean over all of them
    kind: str = "static"  # "static" or "hebbian"
    hebb_rule: str = "ABCD_lr"
    init_weights: str = "uni"

    def build(self, render_mode: str | None = None) -> "Problem":
        return Problem(self, render_mode)


def network_spec(env: gym.Env, recipe: Recipe) -> NetworkSpec:
    """The network an environment (already wrapped by its recipe) needs."""
    inner = env.unwrapped.action_space
    n_actions = inner.shape[0] if isinstance(inner, spaces.Box) else int(inner.n)
    return NetworkSpec(tuple(env.observation_space.shape), n_actions, recipe.squash_output)


def make_policy(spec: ProblemSpec, net: NetworkSpec, recipe: Recipe):
    if spec.kind == "static":
        return StaticPolicy(net)
    if spec.kind == "hebbian":
        return HebbianPolicy(net, spec.hebb_rule, spec.init_weights, normalise=recipe.normalise_hebbian)
    raise ValueError(f"unknown policy kind {spec.kind!r}; valid kinds: static, hebbian")


class Problem:
    def __init__(self, spec: ProblemSpec, render_mode: str | None = None):
        self.spec = spec
        self.envs: list[gym.Env] = []
        self.recipes: list[Recipe] = []
        for env_id in spec.env_ids:
            env, recipe = make_env(env_id, render_mode)
            self.envs.append(env)
            self.recipes.append(recipe)
        self.net = network_spec(self.envs[0], self.recipes[0])
        for env_id, env, recipe in zip(spec.env_ids, self.envs, self.recipes):
            self._check_compatible(env_id, network_spec(env, recipe), recipe)
        self.policy = make_policy(spec, self.net, self.recipes[0])

    def _check_compatible(self, env_id: str, net: NetworkSpec, recipe: Recipe) -> None:
        first = self.spec.env_ids[0]
        if net != self.net:
            self.close()
            raise ValueError(f"{env_id} needs network {net.obs_shape} -> {net.n_actions} (output tanh: "
                             f"{net.squash_out}) but {first} needs {self.net.obs_shape} -> "
                             f"{self.net.n_actions} (output tanh: {self.net.squash_out}); "
                             "environments used together must share observation and action sizes")
        if recipe.normalise_hebbian != self.recipes[0].normalise_hebbian and self.spec.kind == "hebbian":
            self.close()
            raise ValueError(f"{env_id} and {first} disagree on Hebbian weight normalisation; "
                             "train them separately")

    def evaluate(self, params, env_index: int, seed: int) -> Episode:
        return rollout(self.envs[env_index], self.policy, params, seed)

    def rebuild(self, env_index: int) -> None:
        """Replace an environment that raised by a fresh one."""
        try:
            self.envs[env_index].close()
        except Exception:  # the env is already broken; a failing close must not hide the retry
            pass
        self.envs[env_index], _ = make_env(self.spec.env_ids[env_index])

    def close(self) -> None:
        for env in self.envs:
            env.close()
