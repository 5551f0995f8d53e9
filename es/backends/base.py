"""What every backend shares: the interface, one generation's inputs and results, and the task
book-keeping that hands out chunks and retries failures, written once.

A backend runs a ``Generation``'s tasks (``es.worker.TASK_DTYPE``) and returns their ``Results`` in
task order, so the outcome never depends on the backend, the number of workers or the scheduling.

Chunks: work is handed out in chunks of about ``CHUNK_SECONDS``, and at most a quarter of a
worker's fair share, so that no worker idles while another finishes a long episode.

Failures: an episode that raises, or a worker that dies (segfault, out of memory, a lost machine),
is retried once (on a fresh environment, or a fresh worker) and reported in ``Results.warnings``. A
second failure of the same task stops the evaluation with an ``EvaluationError`` naming the
member, the environment and the error.
"""

from __future__ import annotations

import collections
import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from es.worker import Statistics

MAX_ATTEMPTS = 2
CHUNK_SECONDS = 0.1

Progress = Callable[[int, int], None]  # (episodes just finished, their env steps)


@dataclass(frozen=True)
class Generation:
    """One generation's work: theta, sigma, the observation statistics and a strategy's extra arrays
    are published once, the tasks say what to run."""

    number: int  # generations done before this one
    theta: np.ndarray  # float32
    sigma: float
    tasks: np.ndarray  # es.worker.TASK_DTYPE
    statistics: Statistics | None = None  # --obs_norm: (mean, std) the policies normalise with
    scale: np.ndarray | None = None  # float32 (dim,): a per-parameter sigma, in place of sigma (PGPE, SNES)
    rows: np.ndarray | None = None  # float32 (members, dim): the members themselves (CMA-ES)

    def extras(self) -> dict[str, np.ndarray]:
        """The strategy's arrays this generation publishes beside theta, by ``es.worker.Worker``
        attribute name, as contiguous float32."""
        arrays = {"scale": self.scale, "rows": self.rows}
        return {name: np.ascontiguousarray(array, dtype=np.float32) for name, array in arrays.items()
                if array is not None}


@dataclass
class Results:
    returns: np.ndarray  # float64, task order
    steps: np.ndarray  # int64, task order
    penalties: np.ndarray  # float64, task order: mean(theta_m^2) over the penalised parameters
    warnings: list[str] = field(default_factory=list)  # episodes that failed once, workers lost
    observations: list = field(default_factory=list)  # task order: the episode's observation sums, or None

    @classmethod
    def empty(cls, n_tasks: int) -> Results:
        return cls(np.zeros(n_tasks), np.zeros(n_tasks, dtype=np.int64), np.zeros(n_tasks),
                   observations=[None] * n_tasks)


class Evaluator(Protocol):
    """The one interface of the serial, process and Ray backends."""

    workers: int

    def evaluate(self, generation: Generation, progress: Progress | None = None) -> Results:
        """Run every task of ``generation``; results in task order."""

    def close(self) -> None:
        """Stop the workers and free what they hold."""


class WorkerStartError(RuntimeError):
    """A worker (process or actor) could not build its environments or start at all."""


def describe_failure(task: np.void, env_ids: tuple[str, ...], how: str, message: str) -> str:
    """'<env> failed <how> for member <m> (episode seed <s>): <message>'."""
    who = "the unperturbed centre" if task["noise_index"] < 0 else f"member {int(task['member'])}"
    return f"{env_ids[int(task['env_index'])]} failed {how} for {who} (episode seed {int(task['seed'])}): {message}"


class EvaluationError(RuntimeError):
    """A task failed twice; the message names the environment, the member and the error."""

    def __init__(self, task: np.void, env_ids: tuple[str, ...], message: str):
        super().__init__(describe_failure(task, env_ids, "twice", message))


class NonFiniteEpisode(EvaluationError):
    """A task whose member's parameters, or an observation or output where its episode failed, were NaN or
    infinite: the same task would meet them again, so it is not retried, and a resume cannot help. ``what``:
    "parameters", "observations" or "output"."""

    def __init__(self, task: np.void, env_ids: tuple[str, ...], generation: int, what: str, message: str):
        RuntimeError.__init__(self, describe_failure(task, env_ids, f"in generation {generation} with non-finite "
                                                                    f"{what}", message))
        self.what = what


class TaskBook:
    """Book-keeping of one generation's tasks: the waiting queue, the results, the failures."""

    def __init__(self, tasks: np.ndarray, env_ids: tuple[str, ...], progress: Progress | None):
        self.tasks, self.env_ids = tasks, env_ids
        self.results = Results.empty(len(tasks))
        self.waiting = collections.deque(range(len(tasks)))
        self.remaining = len(tasks)
        self._failures = np.zeros(len(tasks), dtype=np.int64)
        self._progress = progress

    def next_chunk(self, size: int, alone: set[int] = frozenset()) -> list[int]:
        """The next ``size`` waiting tasks, or a task of ``alone`` by itself."""
        chunk = [self.waiting.popleft()]
        if chunk[0] in alone:
            return chunk
        while len(chunk) < size and self.waiting and self.waiting[0] not in alone:
            chunk.append(self.waiting.popleft())
        return chunk

    def put_back(self, indices: Iterable[int]) -> None:
        """Unfinished tasks go back to the front of the queue, in order."""
        self.waiting.extendleft(reversed(list(indices)))

    def record(self, index: int, kind: str, payload) -> None:
        """A worker's outcome for task ``index``: its result, an error (retried once), or NaN or infinity."""
        if kind == "nonfinite":
            raise NonFiniteEpisode(self.tasks[index], self.env_ids, *payload)
        if kind == "error":
            self.failed(index, payload)
            self.waiting.appendleft(index)
            return
        total_return, steps, penalty, observations = payload
        results = self.results
        results.returns[index], results.steps[index], results.penalties[index] = total_return, steps, penalty
        results.observations[index] = observations
        self.remaining -= 1
        if self._progress is not None:
            self._progress(1, steps)

    def note(self, message: str) -> None:
        """A warning for the user (a worker lost, its episodes run again)."""
        self.results.warnings.append(message)

    def failed(self, index: int, message: str) -> None:
        """The first failure of a task is reported and retried; the second stops the evaluation."""
        self._failures[index] += 1
        if self._failures[index] >= MAX_ATTEMPTS:
            raise EvaluationError(self.tasks[index], self.env_ids, message)
        self.results.warnings.append(describe_failure(self.tasks[index], self.env_ids, "once", message)
                                    + "; retried")


class ChunkSizer:
    """Tasks per hand-out, from the wall time per task of the last generation."""

    def __init__(self, workers: int):
        self.workers = workers
        self._task_seconds: float | None = None  # None: no generation yet, so single episodes
        self._started = 0.0

    def size(self, n_tasks: int) -> int:
        """About CHUNK_SECONDS of work, at most a quarter of a worker's fair share."""
        self._started = time.perf_counter()
        if self._task_seconds is None:
            return 1
        fair_share = max(1, n_tasks // (4 * self.workers))
        return max(1, min(fair_share, math.ceil(CHUNK_SECONDS / max(self._task_seconds, 1e-6))))

    def finished(self, n_tasks: int) -> None:
        self._task_seconds = (time.perf_counter() - self._started) * self.workers / max(n_tasks, 1)
