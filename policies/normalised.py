"""Observation normalisation (``--obs_norm``) as an input transform of the policy.

Salimans et al. (2017) feed the network (obs - mean) / std, optionally clipped (es-starter clips
at +-5), with running statistics kept by the ES (``es.observations``). Here that transform is a
wrapper around any policy kind, ``NormalisedInputs``, rather than an environment wrapper or a
branch in the rollout, because the statistics are part of the function the evolved parameters
compute (es-starter stores them in the policy and saves them with its weights):

- the rollout stays the one loop, unchanged, and everything that runs a policy through it
  (training, evaluation, the adaptation trace, videos, benchmarks) normalises alike;
- it sees exactly the observations the network acts on (es-starter's statistics), not the last
  one an episode ends with, nor the pyBullet ant's burn-in;
- static and Hebbian networks alike get normalised inputs: the input layer, and so the Hebbian
  rule's pre-synaptic activity, sees them;
- it only needs the network's spec: pixel networks are never wrapped (their CNN sees pixels in
  [0, 1]; ``policies.registry`` skips them and the scripts say so).

The statistics are set per generation from what the runner published (``observe``), never
changed within an episode. What an episode adds up of the raw observations (for the runner's
running statistics) lives in the episode's own state, not in the policy, so the policy is the same
function for every episode it runs; the runner asks for the sums it records (``observation_sums``).
One compiled call per step normalises and adds up.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from policies.base import FrontEnd, Policy, Statistics, Sums


@njit(cache=True, nogil=True)
def _normalise(obs, mean, std, clip, out, total, squares):
    """out = clip((obs - mean) / std, -clip, clip); add obs and obs^2 to the sums."""
    for index in range(out.shape[0]):
        value = np.float64(obs[index])
        total[index] += value
        squares[index] += value * value
        scaled = (value - mean[index]) / std[index]
        out[index] = min(max(scaled, -clip), clip)


@dataclass
class NormalisedState:
    inner: Any  # the wrapped policy's episode state
    out: np.ndarray  # float32: the normalised observation the wrapped policy reads
    total: np.ndarray  # the episode's sum of raw observations, float64
    squares: np.ndarray  # and of their squares
    count: int = 0  # how many it added up


class NormalisedInputs(FrontEnd):
    """``policy`` acting on normalised observations."""

    def __init__(self, policy: Policy, size: int, clip: float | None = None):
        super().__init__(policy)
        self.normalised_inputs = size
        self.obs_clip = clip
        self._clip = np.inf if clip is None else float(clip)
        self._mean, self._std = np.zeros(size), np.ones(size)  # no data yet: the identity

    def observe(self, statistics: Statistics) -> None:
        mean, std = statistics
        if mean.shape != (self.normalised_inputs,) or std.shape != mean.shape:
            raise ValueError(f"observation statistics of shape {mean.shape} for a network with "
                             f"{self.normalised_inputs} inputs")
        self._mean, self._std = np.asarray(mean, np.float64), np.asarray(std, np.float64)

    def observation_sums(self, state: NormalisedState) -> Sums:
        return state.total.copy(), state.squares.copy(), state.count

    def reset(self, params: np.ndarray, rng: np.random.Generator) -> NormalisedState:
        size = self.normalised_inputs
        return NormalisedState(self.inner.reset(params, rng), np.zeros(size, dtype=np.float32), np.zeros(size),
                               np.zeros(size))

    def act(self, params: np.ndarray, state: NormalisedState, obs: np.ndarray):
        _normalise(obs, self._mean, self._std, self._clip, state.out, state.total, state.squares)
        state.count += 1
        output, state.inner = self.inner.act(params, state.inner, state.out)
        return output, state
