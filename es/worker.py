"""What a worker does with a task: rebuild the member's parameters from the noise table, run the episode.

The wire protocol (docs/how-it-works.md, "The worker protocol") is the same for every backend. Per
generation the runner publishes theta, sigma and, with ``--obs_norm``, the observation statistics (mean,
std) once; a task is then one record of ``TASK_DTYPE``

    (member, noise_index, sign, env_index, seed, record_obs, max_steps)

and its outcome ``("result", (return, env steps, L2 penalty, observation sums))``, ``("error", message)``
or ``("nonfinite", (generation, what, message))``. ``noise_index < 0`` is the unperturbed centre, theta
itself; otherwise the member is theta + sign * sigma * noise[noise_index : noise_index + dim]. Two strategies need more,
published once per generation beside theta through the same path (``es.backends``: shared memory,
Ray's object store), never per task: a per-parameter sigma (``scale``: PGPE, SNES), which replaces
the scalar sigma, and the members' own vectors (``rows``: CMA-ES, whose samples cannot come from
the noise table), where a member is ``rows[noise_index]``. The L2 penalty
of the original's fitness, mean(theta_m^2) over the policy's penalised part, is computed here, where
the member's parameters already exist, so that the runner never rebuilds a perturbed vector. The
observation sums (sum, sum of squares, count; ``es.observations``) are those of the observations
the policy acted on, for a task with ``record_obs`` set, and None otherwise.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable

import numpy as np

from es.noise import NoiseTable
from es.shaping import l2_penalty

TASK_DTYPE = np.dtype([("member", np.int64), ("noise_index", np.int64), ("sign", np.int64),
                       ("env_index", np.int64), ("seed", np.int64), ("record_obs", np.int64),
                       ("max_steps", np.int64)])  # max_steps: the episode's cap on policy steps, 0 for none
# ("result", (return, steps, penalty, observation sums)), ("error", message), or ("nonfinite", (generation,
# what, message)): the member's parameters, or an observation or output of its episode, NaN or infinite
Outcome = tuple[str, object]
Statistics = tuple[np.ndarray, np.ndarray]  # (mean, std) of the observations, as published


def make_tasks(members: np.ndarray, noise_indices: np.ndarray, signs: np.ndarray,
               seeds: np.ndarray, n_envs: int, record: np.ndarray | None = None, max_steps: int = 0) -> np.ndarray:
    """All episodes of a generation: every member on every env and seed, member-major.

    ``seeds[m]`` are member m's episode seeds (shape (members, episodes)); mirrored members get the
    same seeds. ``record[m]`` (shaped as ``seeds``; default none) says which of member m's episodes
    add their observations to the statistics, on every environment. ``max_steps`` caps every episode's
    policy steps (0: no cap).
    """
    seeds = np.asarray(seeds, dtype=np.int64)
    record = np.zeros(seeds.shape, dtype=bool) if record is None else np.asarray(record, dtype=bool)
    per_member = n_envs * seeds.shape[1]
    tasks = np.empty(len(members) * per_member, dtype=TASK_DTYPE)
    tasks["member"] = np.repeat(members, per_member)
    tasks["noise_index"] = np.repeat(noise_indices, per_member)
    tasks["sign"] = np.repeat(signs, per_member)
    tasks["env_index"] = np.tile(np.repeat(np.arange(n_envs), seeds.shape[1]), len(members))
    tasks["seed"] = np.repeat(seeds[:, None, :], n_envs, axis=1).reshape(-1)
    tasks["record_obs"] = np.repeat(record[:, None, :], n_envs, axis=1).reshape(-1)
    tasks["max_steps"] = max_steps
    return tasks


def pin_threads() -> None:
    """One BLAS/OpenMP thread per worker: the pool provides the parallelism.

    Libraries read these when they load, so they must be set before a worker process starts
    (child processes inherit them); torch's own setting is made where torch is used.
    """
    for variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ[variable] = "1"


def perturb(theta: np.ndarray, epsilon: np.ndarray, sign: int, sigma: float | np.ndarray) -> np.ndarray:
    """A member's parameters, theta + sign * sigma * epsilon, in float32; ``sigma`` a number or a
    float32 vector (a per-parameter sigma). A sum beyond float32's range is infinite, without a warning:
    ``Worker.run`` names such a member's parameters."""
    with np.errstate(over="ignore", invalid="ignore"):
        if isinstance(sigma, np.ndarray):
            return theta + (np.float32(sign) * sigma) * epsilon
        return theta + np.float32(sign * sigma) * epsilon


class Worker:
    """Holds a built problem (its environments are made once) and evaluates tasks.

    The problem has ``evaluate(params, env_index, seed) -> episode`` (with ``total_return`` and
    ``steps``), ``rebuild(env_index)``, ``close()``, and ``policy.penalised``, the slice of the
    parameters that the L2 term covers.
    """

    def __init__(self, build_problem: Callable[[], object], noise: NoiseTable, theta: np.ndarray):
        self.problem = build_problem()
        self.noise = noise
        self.theta = theta  # read-only here; the runner writes it between generations
        self.scale: np.ndarray | None = None  # a per-parameter sigma, when the generation publishes one
        self.rows: np.ndarray | None = None  # the members' vectors, when the generation publishes them
        self._cached: tuple | None = None
        self._params: np.ndarray | None = None
        self._penalty = 0.0

    def params(self, generation: int, sigma: float, member: int, noise_index: int, sign: int) -> np.ndarray:
        key = (generation, member)
        if self._cached != key:
            if noise_index < 0:
                self._params = np.array(self.theta, dtype=np.float32)
            elif self.rows is not None:
                self._params = np.array(self.rows[noise_index], dtype=np.float32)
            else:
                epsilon = self.noise.slice(noise_index, self.theta.size)
                self._params = perturb(self.theta, epsilon, sign, sigma if self.scale is None else self.scale)
            self._penalty = l2_penalty(self._params[self.problem.policy.penalised])
            self._cached = key
        return self._params

    def run(self, generation: int, sigma: float, task: np.void, statistics: Statistics | None = None) -> Outcome:
        """("result", (return, steps, penalty, observation sums)), ("error", message) after remaking the
        environment, or ("nonfinite", (generation, what, message)) where the member's parameters, or an
        observation or output that failed its episode, are NaN or infinite. ``statistics``: the published
        (mean, std) of the observations, with --obs_norm."""
        env_index = int(task["env_index"])
        try:
            params = self.params(generation, sigma, int(task["member"]), int(task["noise_index"]), int(task["sign"]))
            if not math.isfinite(self._penalty):  # mean(params^2) in float64: not finite only if a parameter is not
                return "nonfinite", (generation + 1, "parameters", self._non_finite_parameters(params, sigma))
            policy = self.problem.policy
            if statistics is not None:
                policy.observe(statistics)
            episode = self.problem.evaluate(params, env_index, int(task["seed"]), int(task["max_steps"]) or None)
            sums = policy.observation_sums(episode.state) if statistics is not None and task["record_obs"] else None
            return "result", (episode.total_return, episode.steps, self._penalty, sums)
        except Exception as error:  # reported to the runner, which retries once, then stops the run
            if getattr(error, "non_finite", None):  # NaN or infinity in the episode (envs.rollout.NonFiniteValues)
                return "nonfinite", (generation + 1, error.non_finite, str(error))  # it would recur: not retried
            message = f"{type(error).__name__}: {error}"
            try:
                self.problem.rebuild(env_index)
            except Exception as rebuild_error:
                message += f" (and remaking the environment failed: {rebuild_error})"
            return "error", message

    def _non_finite_parameters(self, params: np.ndarray, sigma: float) -> str:
        bad = params.size - np.count_nonzero(np.isfinite(params))
        if self.rows is not None:
            source = "as the strategy sampled them"
        else:
            largest = float(np.max(self.scale)) if self.scale is not None else sigma
            source = f"theta + sigma * noise with sigma {largest:g} leaves float32's range"
        return f"{bad} of {params.size} values are NaN or infinite ({source})"

    def close(self) -> None:
        self.problem.close()
