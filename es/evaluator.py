"""Evaluators: run a generation's tasks and return the results in task order.

- ``SerialEvaluator`` runs them in this process (``--threads 1``, tests).
- ``ProcessEvaluator`` keeps persistent worker processes for the whole run. Each worker builds its
  environments once, maps the shared noise table and a shared theta, and receives only task
  integers. Work is handed out in chunks sized to about a tenth of a second, so no core idles
  while another finishes a long episode; results are written back by task index, so the outcome
  does not depend on the number of workers or on scheduling.

Failures: an episode that raises, or a worker process that dies (segfault, out of memory), is
retried once (on a fresh environment, or a fresh process) and reported in ``Results.retried``. A
second failure of the same task stops the evaluation with an ``EvaluationError`` that names the
member, the environment and the error.
"""

from __future__ import annotations

import collections
import ctypes
import math
import multiprocessing as mp
import signal
import sys
import time
from dataclasses import dataclass, field
from multiprocessing import connection, shared_memory
from typing import Callable

import numpy as np

from es.noise import NoiseTable, attach_shared
from es.worker import Worker, pin_threads

MAX_ATTEMPTS = 2
CHUNK_SECONDS = 0.1
CLOSE_SECONDS = 2.0  # how long closing waits for workers to finish before ending them

Progress = Callable[[int, int], None]  # (episodes done, env steps of that episode)


def describe_failure(task: np.ndarray, env_ids: tuple[str, ...], how: str, message: str) -> str:
    """'<env> failed <how> for member <m> (episode seed <s>): <message>'."""
    member, noise_index, _, env_index, seed = (int(value) for value in task)
    who = "the unperturbed centre" if noise_index < 0 else f"member {member}"
    return f"{env_ids[env_index]} failed {how} for {who} (episode seed {seed}): {message}"


class WorkerStartError(RuntimeError):
    """A worker (process or actor) could not build its environments or start at all."""


class EvaluationError(RuntimeError):
    """A task failed twice; the message names the environment, the member and the error."""

    def __init__(self, task: np.ndarray, env_ids: tuple[str, ...], message: str):
        super().__init__(describe_failure(task, env_ids, "twice", message))


@dataclass
class Results:
    returns: np.ndarray  # float64, task order
    steps: np.ndarray  # int64, task order
    retried: list[str] = field(default_factory=list)  # one message per episode that failed once


class _Attempts:
    """Counts failures per task: the first is recorded and retried, the second is fatal."""

    def __init__(self, tasks: np.ndarray, env_ids: tuple[str, ...], retried: list[str]):
        self.tasks, self.env_ids, self.retried = tasks, env_ids, retried
        self.failures = np.zeros(len(tasks), dtype=np.int64)

    def failed(self, task_index: int, message: str) -> None:
        self.failures[task_index] += 1
        if self.failures[task_index] >= MAX_ATTEMPTS:
            raise EvaluationError(self.tasks[task_index], self.env_ids, message)
        self.retried.append(describe_failure(self.tasks[task_index], self.env_ids, "once", message)
                            + "; retried")


class _Generation:
    """Book-keeping of one generation's tasks: results, the queue, the failures."""

    def __init__(self, tasks: np.ndarray, env_ids: tuple[str, ...], progress: Progress | None):
        n_tasks = len(tasks)
        self.results = Results(np.zeros(n_tasks), np.zeros(n_tasks, dtype=np.int64))
        self.attempts = _Attempts(tasks, env_ids, self.results.retried)
        self.waiting = collections.deque(range(n_tasks))
        self.remaining = n_tasks
        self._progress = progress

    def record(self, index: int, kind: str, payload) -> None:
        if kind == "error":
            self.attempts.failed(index, payload)
            self.waiting.appendleft(index)
            return
        total_return, steps = payload
        self.results.returns[index], self.results.steps[index] = total_return, steps
        self.remaining -= 1
        if self._progress is not None:
            self._progress(1, steps)


def chunk_size(n_tasks: int, workers: int, task_seconds: float | None) -> int:
    """Tasks per hand-out: about CHUNK_SECONDS of work, at most a quarter of a worker's fair share.

    ``task_seconds`` is the last generation's wall time per task per worker (None: no generation
    yet, so single episodes are handed out).
    """
    if task_seconds is None:
        return 1
    fair_share = max(1, n_tasks // (4 * workers))
    return max(1, min(fair_share, math.ceil(CHUNK_SECONDS / max(task_seconds, 1e-6))))


class SerialEvaluator:
    def __init__(self, build_problem: Callable[[], object], noise: NoiseTable, dim: int,
                 env_ids: tuple[str, ...]):
        self.env_ids = env_ids
        self._theta = np.zeros(dim, dtype=np.float32)
        self._worker = Worker(build_problem, noise, self._theta)
        self.workers = 1

    def evaluate(self, generation: int, theta: np.ndarray, sigma: float, tasks: np.ndarray,
                 progress: Progress | None = None) -> Results:
        self._theta[:] = theta
        run = _Generation(tasks, self.env_ids, progress)
        while run.waiting:
            index = run.waiting.popleft()
            run.record(index, *self._worker.run(generation, sigma, tasks[index]))
        return run.results

    def close(self) -> None:
        self._worker.close()


# --- process pool --------------------------------------------------------------------------------


def _die_with_parent() -> None:
    """Linux: have the kernel kill this worker if the run's process dies, even by SIGKILL."""
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass


def _worker_main(conn, build_problem, noise_name: str, noise_size: int, theta_name: str, dim: int) -> None:
    _die_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the runner's to handle
    pin_threads()
    try:
        noise = NoiseTable.attach(noise_name, noise_size)
        theta_memory = attach_shared(theta_name)
        theta = np.ndarray((dim,), dtype=np.float32, buffer=theta_memory.buf)
        worker = Worker(build_problem, noise, theta)
    except Exception as error:
        conn.send(("fatal", f"{type(error).__name__}: {error}"))
        return
    conn.send(("ready", None))
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):  # the runner is gone
            break
        if message is None:
            break
        generation, sigma, chunk = message
        for task in chunk:
            conn.send(worker.run(generation, sigma, task))
        conn.send(("done", None))
    worker.close()


def _context():
    methods = mp.get_all_start_methods()
    return mp.get_context("forkserver" if "forkserver" in methods else "spawn")


class _Slot:
    """One worker process and what it is working on."""

    def __init__(self, process, conn):
        self.process, self.conn = process, conn
        self.chunk: collections.deque = collections.deque()  # task indices not yet reported


class ProcessEvaluator:
    def __init__(self, build_problem: Callable[[], object], noise: NoiseTable, dim: int,
                 env_ids: tuple[str, ...], workers: int):
        if noise.name is None:
            raise ValueError("the process pool needs a noise table in shared memory")
        self.env_ids, self.workers = env_ids, workers
        self._args = (build_problem, noise.name, noise.size)
        self._dim = dim
        self._theta_memory = shared_memory.SharedMemory(create=True, size=max(dim, 1) * 4)
        self._theta = np.ndarray((dim,), dtype=np.float32, buffer=self._theta_memory.buf)
        pin_threads()  # here, before the workers (and the fork server) start and load their libraries
        self._context = _context()
        self._slots: list[_Slot] = []
        self._task_seconds: float | None = None
        try:
            self._slots = [self._spawn() for _ in range(workers)]  # they start in parallel
            for slot in self._slots:
                self._await_ready(slot)
        except BaseException:
            self.close()
            raise

    def _spawn(self) -> _Slot:
        parent, child = self._context.Pipe()
        build_problem, noise_name, noise_size = self._args
        process = self._context.Process(
            target=_worker_main, daemon=True,
            args=(child, build_problem, noise_name, noise_size, self._theta_memory.name, self._dim))
        process.start()
        child.close()
        return _Slot(process, parent)

    @staticmethod
    def _await_ready(slot: _Slot) -> None:
        try:
            kind, payload = slot.conn.recv()
        except EOFError:
            slot.process.join(timeout=5)
            kind, payload = "fatal", f"worker process exited while starting ({_describe_exit(slot.process)})"
        if kind != "ready":
            raise WorkerStartError(f"a worker could not start: {payload}")

    def evaluate(self, generation: int, theta: np.ndarray, sigma: float, tasks: np.ndarray,
                 progress: Progress | None = None) -> Results:
        self._theta[:] = theta
        started = time.perf_counter()
        run = _Generation(tasks, self.env_ids, progress)
        size = chunk_size(len(tasks), self.workers, self._task_seconds)
        idle = list(self._slots)
        busy: dict = {}  # connection or process sentinel -> slot
        while run.remaining or busy:  # busy: wait for every "done", so no message is left over
            while idle and run.waiting:
                slot = idle.pop()
                slot.chunk = collections.deque(run.waiting.popleft()
                                               for _ in range(min(size, len(run.waiting))))
                slot.conn.send((generation, sigma, [tasks[index] for index in slot.chunk]))
                busy[slot.conn] = busy[slot.process.sentinel] = slot
            for ready in connection.wait(list(busy)):
                slot = busy.get(ready)
                if slot is None:  # handled already through its other handle
                    continue
                if self._receive(slot, run, block=ready is slot.conn):
                    del busy[slot.conn], busy[slot.process.sentinel]
                    idle.append(slot if slot.process.is_alive() and not slot.chunk else self._replace(slot, run))
        self._task_seconds = (time.perf_counter() - started) * self.workers / max(len(tasks), 1)
        return run.results

    def _receive(self, slot: _Slot, run: "_Generation", block: bool) -> bool:
        """Read what ``slot`` sent; True once it is finished with its chunk (or dead)."""
        try:
            while block or slot.conn.poll():
                block = False
                kind, payload = slot.conn.recv()
                if kind == "done":
                    return True
                run.record(slot.chunk.popleft(), kind, payload)
        except (EOFError, OSError):
            return True
        return not slot.process.is_alive()

    def _replace(self, slot: _Slot, run: "_Generation") -> _Slot:
        """Start a fresh worker for a dead one; its unfinished tasks go back in the queue."""
        slot.process.join(timeout=5)
        slot.conn.close()
        lost = list(slot.chunk)
        run.waiting.extendleft(reversed(lost))
        fresh = self._spawn()
        self._await_ready(fresh)
        self._slots[self._slots.index(slot)] = fresh
        if lost:  # the first unreported task is the one it was running
            run.attempts.failed(lost[0], f"worker process died ({_describe_exit(slot.process)})")
        return fresh

    def close(self) -> None:
        """Ask every worker to stop; after CLOSE_SECONDS in all, end the ones still busy (or stuck)."""
        for slot in self._slots:
            try:
                slot.conn.send(None)
            except (OSError, ValueError):
                pass
        deadline = time.monotonic() + CLOSE_SECONDS
        for slot in self._slots:
            slot.process.join(timeout=max(0.0, deadline - time.monotonic()))
        for slot in self._slots:
            if slot.process.is_alive():
                slot.process.terminate()
                slot.process.join(timeout=CLOSE_SECONDS)
            if slot.process.is_alive():
                slot.process.kill()
                slot.process.join()
            slot.conn.close()
        self._slots = []
        if self._theta_memory is not None:
            self._theta = np.empty(0, dtype=np.float32)
            self._theta_memory.close()
            self._theta_memory.unlink()
            self._theta_memory = None


def _describe_exit(process) -> str:
    code = process.exitcode
    if code is not None and code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"
