"""The one episode loop, used by training, evaluation, benchmarks and tests."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np


class NonFiniteValues(ValueError):
    """An episode met NaN or infinity where no result can come from it: an observation after reset or after
    the last step, or the observation or the network's output of a step that then failed. ``non_finite``
    names which (the training's workers, ``es.worker``, know it by that attribute alone)."""

    def __init__(self, non_finite: str, message: str):
        super().__init__(message)
        self.non_finite = non_finite


def non_finite(values) -> bool:
    """Whether a float array (an observation, a network's output) holds NaN or infinity."""
    return isinstance(values, np.ndarray) and values.dtype.kind == "f" and not np.isfinite(values).all()


def shown(values: np.ndarray) -> str:
    """The first values of an array, for a message."""
    flat = values.ravel()
    return np.array2string(flat[:4], precision=3) + (f" ... ({flat.size} values)" if flat.size > 4 else "")


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
    if non_finite(observation):  # checked once an episode: an environment's NaN shows from its reset on
        raise NonFiniteValues("observations", f"the observation after reset is not finite: {shown(observation)}")
    burn_in = int(info.get("burn_in_steps", 0))
    limit = None if max_steps is None else max(1, max_steps - burn_in)  # in policy steps
    state = policy.reset(params, episode_rng(seed))
    act, step = policy.act, env.step
    total, steps, output = 0.0, 0, None
    try:
        while True:
            output, state = act(params, state, observation)
            observation, reward, terminated, truncated, info = step(output)
            total += reward
            steps += 1
            if observer is not None:
                observer(steps, float(reward), state, info)
            if terminated or truncated or steps == limit:
                break
    except Exception as error:  # name NaN or infinity where it led to the failure
        failure = f"{type(error).__name__}: {error}"
        if non_finite(observation):
            raise NonFiniteValues("observations", f"the observation before step {steps + 1} is not finite: "
                                                  f"{shown(observation)}; the step failed with {failure}") from error
        if non_finite(output):
            raise NonFiniteValues("output", f"the network's output at step {steps + 1} is not finite: "
                                            f"{shown(output)}; the step failed with {failure}") from error
        raise
    if non_finite(observation):  # and once at its end: where it shows mid-episode, it mostly stays
        raise NonFiniteValues("observations", f"the observation after the last step ({steps}) is not finite: "
                                              f"{shown(observation)}")
    return Episode(float(total), steps + burn_in, state)
