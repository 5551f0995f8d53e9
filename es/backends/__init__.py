"""Backends: where a generation's episodes run. One interface (``Evaluator``), three implementations.

    serial    this process (--threads 1, tests)
    process   persistent worker processes on this machine (the default)
    ray       Ray actors, on one machine or a cluster (optional: pip install -r requirements-ray.txt)

All three speak the same wire protocol (``es.worker``) and put results back in task order, so a
given seed gives the same theta on any of them, with any number of workers.
"""

from __future__ import annotations

from collections.abc import Callable

from es.backends.base import (
    EvaluationError,
    Evaluator,
    Generation,
    NonFiniteEpisode,
    Progress,
    Results,
    TaskBook,
    WorkerStartError,
)
from es.backends.process import ProcessEvaluator
from es.backends.serial import SerialEvaluator
from es.noise import NoiseTable
from es.settings import BACKENDS, RunSettings

RAY_INSTALL_HINT = "install it with: pip install -r requirements-ray.txt (or pip install -e .[ray])"


class BackendUnavailable(ValueError):
    """The chosen backend cannot be used here (not installed, unknown)."""


def make_evaluator(run: RunSettings, build_problem: Callable[[], object], noise: NoiseTable, dim: int,
                   env_ids: tuple[str, ...], problem: object) -> Evaluator:
    """The evaluator ``run`` asks for; ``problem`` (built already) is reused by the serial one, closed otherwise."""
    if run.in_process:
        return SerialEvaluator(lambda: problem, noise, dim, env_ids)
    problem.close()
    if run.backend == "process":
        return ProcessEvaluator(build_problem, noise, dim, env_ids, run.workers, problem.policy.worker_modules)
    if run.backend == "ray":
        try:
            from es.backends.ray import RayEvaluator
        except ModuleNotFoundError as error:
            if error.name != "ray":
                raise
            raise BackendUnavailable(f"--backend ray needs Ray, which is not installed; {RAY_INSTALL_HINT}") from None
        workers = None if run.threads == -1 else run.threads  # -1: one per CPU Ray reports
        return RayEvaluator(build_problem, noise, dim, env_ids, workers, run.ray_address)
    raise BackendUnavailable(f"unknown backend {run.backend!r}; valid backends: {', '.join(BACKENDS)}")


__all__ = ["BACKENDS", "BackendUnavailable", "EvaluationError", "Evaluator", "Generation", "NonFiniteEpisode",
           "ProcessEvaluator", "Progress", "Results", "SerialEvaluator", "TaskBook", "WorkerStartError",
           "make_evaluator"]
