"""The one episode loop, used by training, evaluation, benchmarks and tests."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np


@dataclass
class Episode:
    total_return: float
    steps: int  # environment steps, burn-in included
    state: Any = field(default=None, repr=False, compare=False)  # the policy's, when the episode ended


def episode_rng(seed: int) -> np.random.Generator:
    """The policy's own random stream for an episode (e.g. Hebbian initial weights).

    It is derived from the episode seed but independent of the environment's stream, so that a
    given (params, seed) gives the same episode in any process.
    """
    return np.random.default_rng([int(seed), 0x4EBB])


def rollout(env: gym.Env, policy, params: np.ndarray, seed: int,
            observer: Callable[[int, float, object, dict], None] | None = None,
            max_steps: int | None = None) -> Episode:
    """Run one episode of ``policy`` with ``params`` on ``env``, reset with ``seed``.

    ``observer(t, reward, state, info)``, if given, is called after every step (evaluation plots).
    ``max_steps`` ends the episode after that many environment steps, a burn-in included, the unit of
    ``Episode.steps`` (``--variable_ep_len``'s cap, which changes from one generation to the next; a
    fixed cap on policy steps is ``envs.wrappers.MaxEpisodeSteps``).
    """
    observation, info = env.reset(seed=int(seed))
    burn_in = int(info.get("burn_in_steps", 0))
    limit = None if max_steps is None else max(1, max_steps - burn_in)  # in policy steps
    state = policy.reset(params, episode_rng(seed))
    act, step = policy.act, env.step
    total, steps = 0.0, 0
    while True:
        output, state = act(params, state, observation)
        observation, reward, terminated, truncated, info = step(output)
        total += reward
        steps += 1
        if observer is not None:
            observer(steps, float(reward), state, info)
        if terminated or truncated or steps == limit:
            break
    return Episode(float(total), steps + burn_in, state)
