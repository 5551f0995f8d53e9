"""What a worker does with a task: rebuild the member's parameters from the noise table, run the episode.

The wire protocol (DESIGN.md) is the same for every backend. Per generation the runner publishes
theta and sigma once; a task is then five integers

    (member, noise_index, sign, env_index, episode_seed)

and its outcome ("result", (return, env steps)) or ("error", message). ``noise_index < 0`` is the unperturbed centre, theta itself.
"""

from __future__ import annotations

import os
from typing import Callable

import numpy as np

from es.noise import NoiseTable

TASK_FIELDS = ("member", "noise_index", "sign", "env_index", "seed")
Outcome = tuple[str, object]  # ("result", (return, steps)) or ("error", message)


def make_tasks(members: np.ndarray, noise_indices: np.ndarray, signs: np.ndarray,
               seeds: np.ndarray, n_envs: int) -> np.ndarray:
    """All episodes of a generation, (n_tasks, 5) int64: every member on every env and seed.

    ``seeds[m]`` are member m's episode seeds; mirrored members get the same seeds.
    """
    rows = [(member, index, sign, env_index, seed)
            for member, index, sign, member_seeds in zip(members, noise_indices, signs, seeds)
            for env_index in range(n_envs)
            for seed in member_seeds]
    return np.array(rows, dtype=np.int64).reshape(-1, len(TASK_FIELDS))


def pin_threads() -> None:
    """One BLAS/OpenMP thread per worker: the pool provides the parallelism.

    Libraries read these when they load, so they must be set before a worker process starts
    (child processes inherit them); torch's own setting is made where torch is used.
    """
    for variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ[variable] = "1"


def perturb(theta: np.ndarray, epsilon: np.ndarray, sign: int, sigma: float) -> np.ndarray:
    """A member's parameters, theta + sign * sigma * epsilon, in float32."""
    return theta + np.float32(sign * sigma) * epsilon


class Worker:
    """Holds a built problem (its environments are made once) and evaluates tasks."""

    def __init__(self, build_problem: Callable[[], object], noise: NoiseTable, theta: np.ndarray):
        self.problem = build_problem()
        self.noise = noise
        self.theta = theta  # read-only here; the runner writes it between generations
        self._cached: tuple | None = None
        self._params: np.ndarray | None = None

    def params(self, generation: int, sigma: float, member: int, noise_index: int, sign: int) -> np.ndarray:
        key = (generation, member)
        if self._cached != key:
            if noise_index < 0:
                self._params = np.array(self.theta, dtype=np.float32)
            else:
                epsilon = self.noise.slice(noise_index, self.theta.size)
                self._params = perturb(self.theta, epsilon, sign, sigma)
            self._cached = key
        return self._params

    def run(self, generation: int, sigma: float, task) -> Outcome:
        """("result", (return, steps)), or ("error", message) after remaking the environment."""
        member, noise_index, sign, env_index, seed = (int(value) for value in task)
        try:
            params = self.params(generation, sigma, member, noise_index, sign)
            episode = self.problem.evaluate(params, env_index, seed)
            return "result", (episode.total_return, episode.steps)
        except Exception as error:  # reported to the runner, which retries once, then stops the run
            message = f"{type(error).__name__}: {error}"
            try:
                self.problem.rebuild(env_index)
            except Exception as rebuild_error:
                message += f" (and remaking the environment failed: {rebuild_error})"
            return "error", message

    def close(self) -> None:
        self.problem.close()
