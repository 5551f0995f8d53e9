"""The Ray backend: the process pool's wire protocol on Ray actors, from one machine to a cluster.

Salimans et al. (2017) scaled ES to 1 440 cores by sending only seeds and returns. Ray Core
(Moritz et al., OSDI 2018) does the sending here, on one machine or many, with the protocol of
docs/how-it-works.md ("The worker protocol") unchanged:

- one long-lived actor per CPU (or per ``--threads``), each holding a ``Worker``: its environments
  are made once per run;
- the noise table is put in the object store once per run; actors on the same node read it in
  place (zero-copy, read-only), actors on other nodes fetch it once;
- theta is put once per generation and only its reference travels with each chunk (with the
  observation statistics of ``--obs_norm``, two vectors of the observation's size), and so are a
  strategy's per-generation arrays (``Generation.extras``: a per-parameter sigma, CMA-ES's
  population matrix);
- a chunk is task rows and their indices, and comes back as (task index, kind, payload) per task;
- chunks hold about 0.1 s of work (``ChunkSizer``, shared with the process pool), are handed out
  as actors finish (``ray.wait``), and results are written back by task index, so the outcome is
  the same as with the serial evaluator and the process pool.

Faults: an episode that raises is retried as on the other backends. An actor that dies (process
killed, node lost) is replaced in the background and its unfinished tasks go back in the queue.
Which task of a chunk killed it is unknown, so those tasks are then re-run one per chunk: the death
of an actor running a single task counts as a failure of that task, and a task's second failure
stops the evaluation with an ``EvaluationError``, as with the process pool.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import signal
import socket
from collections.abc import Callable

import numpy as np
import ray
from ray.exceptions import RayActorError, RayError

from es.backends.base import ChunkSizer, Generation, Progress, Results, TaskBook, WorkerStartError
from es.noise import NoiseTable
from es.worker import Worker, pin_threads

WAIT_SECONDS = 0.5  # ray.wait wakes up this often, so a second Ctrl-C is handled promptly
REACH_SECONDS = 5  # to open a TCP connection to --ray_address HOST:PORT
QUIET_DEFAULTS = {"RAY_USAGE_STATS_ENABLED": "0"}  # no usage-stats notice (or upload) per run


def start_ray(address: str | None, num_cpus: int | None) -> bool:
    """Start a local Ray (``address`` None) or join a cluster; False if this process already has one.

    A local Ray is a new one even where ``ray start`` runs a cluster on this machine (Ray's own
    default would join it). Actor output is not forwarded to this terminal (pyBullet prints a line
    per environment), and only Ray's errors are logged here.
    """
    if ray.is_initialized():
        return False
    for name, value in QUIET_DEFAULTS.items():
        os.environ.setdefault(name, value)
    options = dict(log_to_driver=False, logging_level=logging.ERROR)
    if address is None:
        options.update(num_cpus=num_cpus, include_dashboard=False)
    elif address != "auto":
        _check_reachable(address)
    try:
        with _interrupts_held():
            ray.init(address=address or "local", **options)
    except KeyboardInterrupt:
        with _interrupts_ignored():
            ray.shutdown()
        raise
    except ConnectionError as error:
        raise ValueError(_connection_problem(address, error)) from None
    return True


def _check_reachable(address: str) -> None:
    """Fail fast where nothing listens: Ray itself retries an unreachable address for minutes."""
    host, _, port = address.rpartition(":")
    if "://" in address:  # ray://... (Ray Client): Ray's own checks apply
        return
    if not host or not port.isdigit():
        raise ValueError(f"--ray_address {address}: expected auto or HOST:PORT, as `ray start --head` prints it")
    try:
        socket.create_connection((host, int(port)), timeout=REACH_SECONDS).close()
    except OSError as error:
        raise ValueError(f"--ray_address {address}: nothing answers there ({error.strerror or error}); "
                         "give the address `ray start --head` printed") from None


def _connection_problem(address: str, error: ConnectionError) -> str:
    if address == "auto":
        return ("--ray_address auto: no Ray cluster runs on this machine; start one with `ray start --head`, "
                "or leave --ray_address out to start a local Ray")
    return (f"--ray_address {address}: {_first_sentence(error)}; a cluster with token authentication "
            "needs RAY_AUTH_MODE=token here too (see docs/cluster.md)")


def actor_count(requested: int | None) -> int:
    """``requested`` actors, or one per CPU the cluster reports; more than its CPUs would never start."""
    cpus = int(ray.cluster_resources().get("CPU", 0))
    if requested is None:
        if cpus < 1:
            raise ValueError("the Ray cluster reports no CPUs; start it with `ray start --num-cpus N`")
        return cpus
    if requested > cpus:
        raise ValueError(f"--threads {requested} is more than the {cpus} CPUs of the Ray cluster; "
                         f"give --threads {cpus} or less, or add machines")
    return requested


def _first_sentence(error: BaseException) -> str:
    text = str(error).strip()
    return text.splitlines()[0].split(". ")[0].rstrip(".") if text else type(error).__name__


def _death_reason(error: RayError) -> str:
    """A short line out of Ray's long report of a dead actor: its exit type and detail."""
    text = " ".join(str(error).split())
    exit_type = re.search(r"Worker exit type: (\w+)", text)
    detail = re.search(r"Worker exit detail: (.+?)\.(?: |$)", text)
    found = [match.group(1) for match in (exit_type, detail) if match]
    return ", ".join(found) if found else _first_sentence(error)


class _WorkerActor:
    """One Ray actor: a ``Worker`` with its environments, reading the noise table in place."""

    def __init__(self, build_problem: Callable[[], object], noise: np.ndarray, dim: int):
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the runner's to handle
        pin_threads()
        self.failure = None
        try:
            self.worker = Worker(build_problem, NoiseTable(noise), np.zeros(dim, dtype=np.float32))
        except Exception as error:  # reported by ready(), in one line
            self.failure = f"{type(error).__name__}: {error}"

    def ready(self) -> str | None:
        """None once the environments are made, else why they could not be."""
        return self.failure

    def run(self, generation: int, sigma: float, theta: np.ndarray, statistics, indices: list[int],
            rows: np.ndarray, scale: np.ndarray | None = None,
            members: np.ndarray | None = None) -> list[tuple[int, str, object]]:
        """Run a chunk; (task index, "result", (return, steps, penalty, observation sums)) or
        (task index, "error", message). ``scale`` and ``members``: the generation's extras."""
        self.worker.theta = theta  # Ray resolved the generation's references: read-only views
        self.worker.scale, self.worker.rows = scale, members
        return [(index, *self.worker.run(generation, sigma, row, statistics)) for index, row in zip(indices, rows)]


_RemoteWorker = ray.remote(num_cpus=1, max_restarts=0)(_WorkerActor)


class RayEvaluator:
    """Evaluates a generation's tasks on Ray actors; the interface of ``ProcessEvaluator``."""

    def __init__(self, build_problem: Callable[[], object], noise: NoiseTable, dim: int,
                 env_ids: tuple[str, ...], workers: int | None = None, address: str | None = None):
        """``workers`` None: one actor per CPU of the cluster; ``address`` None: start a local Ray."""
        self.env_ids, self._build_problem, self._dim = env_ids, build_problem, dim
        self._actors: list = []
        self._starting: dict = {}  # ready() reference -> actor not yet ready
        self._noise = None
        self._owns_ray = start_ray(address, workers)
        try:
            self.workers = actor_count(workers)
            self._chunks = ChunkSizer(self.workers)
            self._noise = ray.put(noise.array)
            for _ in range(self.workers):  # they start in parallel
                self._launch()
            for ready in list(self._starting):
                self._started(ready)
        except BaseException:
            self.close()
            raise

    def _launch(self) -> None:
        actor = _RemoteWorker.remote(self._build_problem, self._noise, self._dim)
        self._starting[actor.ready.remote()] = actor

    def _started(self, ready) -> object:
        actor = self._starting.pop(ready)
        try:
            failure = ray.get(ready)
        except RayError as error:
            failure = f"its process died ({_death_reason(error)})"
        if failure is not None:
            ray.kill(actor, no_restart=True)
            raise WorkerStartError(f"a worker could not start: {failure}")
        self._actors.append(actor)
        return actor

    def evaluate(self, generation: Generation, progress: Progress | None = None) -> Results:
        tasks = generation.tasks
        book = TaskBook(tasks, self.env_ids, progress)
        theta_ref = ray.put(np.ascontiguousarray(generation.theta, dtype=np.float32))
        extras = {name: ray.put(array) for name, array in generation.extras().items()}
        scale_ref, members_ref = extras.get("scale"), extras.get("rows")  # top-level arguments: Ray resolves them
        size = self._chunks.size(len(tasks))
        suspects: set[int] = set()  # tasks of a chunk whose actor died: re-run one at a time
        idle = list(self._actors)
        in_flight: dict = {}  # result reference -> (actor, task indices)
        while book.remaining:
            while idle and book.waiting:
                actor, indices = idle.pop(), book.next_chunk(size, alone=suspects)
                if indices[0] in suspects and (death := self._death(actor)) is not None:
                    # a task whose worker died runs again alone, so that it is charged if it kills
                    # its worker; it goes only to a worker seen alive: one lost at the same time as
                    # the first (a node going down), whose last chunk came back, charges no task
                    book.put_back(indices)
                    self._replace(actor, [], book, suspects, death)
                    continue
                reference = actor.run.remote(generation.number, generation.sigma, theta_ref, generation.statistics,
                                             indices, tasks[indices], scale_ref, members_ref)
                in_flight[reference] = actor, indices
            done, _ = ray.wait([*in_flight, *self._starting], num_returns=1, timeout=WAIT_SECONDS)
            for ref in done:
                if ref in self._starting:
                    idle.append(self._started(ref))
                    continue
                actor, indices = in_flight.pop(ref)
                try:
                    outcomes = ray.get(ref)
                except RayActorError as error:
                    self._replace(actor, indices, book, suspects, error)
                    continue
                for index, kind, payload in outcomes:
                    book.record(index, kind, payload)
                idle.append(actor)
        self._chunks.finished(len(tasks))
        return book.results

    @staticmethod
    def _death(actor) -> RayActorError | None:
        """Why ``actor`` is dead, or None if it answers."""
        try:
            ray.get(actor.ready.remote())
        except RayActorError as error:
            return error
        return None

    def _replace(self, actor, indices: list[int], book: TaskBook, suspects: set[int],
                 error: RayActorError) -> None:
        """Start a fresh actor for a dead one; its unfinished tasks go back in the queue."""
        self._actors.remove(actor)
        ray.kill(actor, no_restart=True)  # it may only be unreachable: make sure it is gone
        self._launch()
        book.put_back(indices)
        suspects.update(indices)
        if len(indices) == 1:  # alone in its chunk: this task is what the actor was running
            book.failed(indices[0], f"Ray worker died ({_death_reason(error)})")
        elif not indices:
            book.note(f"a Ray worker died ({_death_reason(error)}); it was replaced")
        else:
            book.note(f"a Ray worker died ({_death_reason(error)}); it was replaced, and its {len(indices)} "
                      "unfinished episodes run again, one at a time")

    def close(self) -> None:
        """Kill the actors; disconnect from Ray if this evaluator connected (a local Ray stops too)."""
        with _interrupts_ignored():
            for actor in [*self._actors, *self._starting.values()]:
                try:
                    ray.kill(actor, no_restart=True)
                except RayError:
                    pass
            self._actors, self._starting, self._noise = [], {}, None
            if self._owns_ray and ray.is_initialized():
                ray.shutdown()
            self._owns_ray = False


def _set_sigint(handler):
    """Install a SIGINT handler; the previous one, or None where this is not the main thread."""
    try:
        return signal.signal(signal.SIGINT, handler)
    except ValueError:  # not the main thread: signals are not ours to handle
        return None


@contextlib.contextmanager
def _interrupts_ignored():
    """Ctrl-C while Ray shuts down (about a second) would leave it half stopped, with a traceback."""
    previous = _set_sigint(signal.SIG_IGN)
    try:
        yield
    finally:
        if previous is not None:
            _set_sigint(previous)


@contextlib.contextmanager
def _interrupts_held():
    """Ctrl-C while Ray starts would leave some of its processes behind: raise it once Ray is up."""
    received = []
    previous = _set_sigint(lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        if previous is not None:
            _set_sigint(previous)
    if received:
        raise KeyboardInterrupt
