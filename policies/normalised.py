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
changed within an episode, and the wrapper adds up the raw observations of the episodes it is
asked to record. One compiled call per step does both.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from policies.base import Policy


@njit(cache=True, nogil=True)
def _normalise(obs, mean, std, clip, out, total, squares, record):
    """out = clip((obs - mean) / std, -clip, clip); with ``record``, add obs and obs^2 to the sums."""
    for index in range(out.shape[0]):
        value = np.float64(obs[index])
        if record:
            total[index] += value
            squares[index] += value * value
        scaled = (value - mean[index]) / std[index]
        out[index] = min(max(scaled, -clip), clip)


class NormalisedInputs:
    """``policy`` acting on normalised observations; every other attribute is the wrapped policy's."""

    def __init__(self, policy: Policy, size: int, clip: float | None = None):
        self.inner = policy
        self.normalised_inputs = size
        self.clip = clip
        self._clip = np.inf if clip is None else float(clip)
        self._mean, self._std = np.zeros(size), np.ones(size)  # no data yet: the identity
        self._out = np.zeros(size, dtype=np.float32)
        self._recording = False
        self._total, self._squares, self._count = np.zeros(size), np.zeros(size), 0

    def __getattr__(self, name: str):
        if name == "inner":  # not set yet (e.g. while unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.inner, name)

    def observe(self, statistics: tuple[np.ndarray, np.ndarray], record: bool = False) -> None:
        """Normalise with (mean, std) from now on; ``record``: add up the next episode's observations."""
        mean, std = statistics
        if mean.shape != (self.normalised_inputs,) or std.shape != mean.shape:
            raise ValueError(f"observation statistics of shape {mean.shape} for a network with "
                             f"{self.normalised_inputs} inputs")
        self._mean, self._std = np.asarray(mean, np.float64), np.asarray(std, np.float64)
        self._recording = record

    def recorded(self) -> tuple[np.ndarray, np.ndarray, int] | None:
        """(sum, sum of squares, count) of the last episode's observations, if it was recorded."""
        return (self._total.copy(), self._squares.copy(), self._count) if self._recording else None

    def reset(self, params: np.ndarray, rng: np.random.Generator):
        self._total[:] = 0.0
        self._squares[:] = 0.0
        self._count = 0
        return self.inner.reset(params, rng)

    def act(self, params: np.ndarray, state, obs: np.ndarray):
        _normalise(obs, self._mean, self._std, self._clip, self._out, self._total, self._squares, self._recording)
        self._count += self._recording
        return self.inner.act(params, state, self._out)
