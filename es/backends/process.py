"""The process-pool backend: persistent worker processes on this machine.

Each worker builds its environments once, maps the shared noise table and a shared theta, and
receives only task records, in chunks (``es.backends.base``). A strategy's per-generation arrays
(a per-parameter sigma, CMA-ES's population matrix: ``Generation.extras``) are written once per
generation into shared segments of their own (``SharedArrays``), made when first needed and remade
only if an array outgrows its segment; a message names the segments, and a worker maps a segment
once, by name. A worker that dies (segfault, out of memory) is replaced and the task it was running
is retried once. Modules the episodes import that are heavy (``preload``: a policy's ``worker_modules``)
are loaded by the fork server before it forks the workers, so that they share those pages: torch
alone is about 120 MiB of private memory per process that imports it.
"""

from __future__ import annotations

import collections
import ctypes
import multiprocessing as mp
import os
import signal
import sys
import time
from collections.abc import Callable
from multiprocessing import connection, shared_memory

import numpy as np

from es.backends.base import ChunkSizer, Generation, Progress, Results, TaskBook, WorkerStartError
from es.noise import NoiseTable, attach_shared
from es.worker import Worker, pin_threads

CLOSE_SECONDS = 2.0  # how long closing waits for workers to finish before ending them


MAX_WORKERS_PER_CORE = 4  # beyond this, more processes only add memory and switching, never speed


def check_workers(workers: int) -> None:
    """Refuse a pool far larger than the machine: each worker is a Python process with its own environments."""
    cores = os.cpu_count() or 1
    if workers > MAX_WORKERS_PER_CORE * cores:
        raise ValueError(f"--threads {workers} would start {workers} worker processes on this machine's {cores} cores; "
                         f"give at most {MAX_WORKERS_PER_CORE * cores}, or -1 for one per core")


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
    mapped = MappedArrays()
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):  # the runner is gone
            break
        if message is None:
            break
        generation, sigma, statistics, extras, chunk = message
        mapped.attach(worker, extras)
        for task in chunk:
            conn.send(worker.run(generation, sigma, task, statistics))
        conn.send(("done", None))
    worker.close()
    mapped.close(worker)


class SharedArrays:
    """The runner's side: named float32 arrays in shared memory, rewritten every generation."""

    def __init__(self):
        self._segments: dict[str, shared_memory.SharedMemory] = {}

    def publish(self, arrays: dict[str, np.ndarray]) -> dict[str, tuple[str, tuple[int, ...]]]:
        """Write ``arrays``; what a worker needs to map them: name -> (segment, shape)."""
        described = {}
        for name, array in arrays.items():
            segment = self._segments.get(name)
            if segment is None or segment.size < array.nbytes:
                self._free(name)
                segment = self._segments[name] = shared_memory.SharedMemory(create=True, size=max(array.nbytes, 4))
            np.ndarray(array.shape, dtype=np.float32, buffer=segment.buf)[...] = array
            described[name] = (segment.name, array.shape)
        return described

    def _free(self, name: str) -> None:
        segment = self._segments.pop(name, None)
        if segment is not None:
            segment.close()
            segment.unlink()

    def close(self) -> None:
        for name in list(self._segments):
            self._free(name)


class MappedArrays:
    """A worker's side: the segments of ``SharedArrays`` it has mapped, set on its ``Worker``."""

    def __init__(self):
        self._segments: dict[str, shared_memory.SharedMemory] = {}  # segment name -> mapping

    def attach(self, worker: Worker, described: dict[str, tuple[str, tuple[int, ...]]]) -> None:
        worker.scale = worker.rows = None  # no view may outlive its mapping
        names = {segment for segment, _ in described.values()}
        for segment in set(self._segments) - names:  # remade larger by the runner
            self._segments.pop(segment).close()
        for attribute, (segment, shape) in described.items():
            if segment not in self._segments:
                self._segments[segment] = attach_shared(segment)
            buffer = self._segments[segment].buf
            setattr(worker, attribute, np.ndarray(shape, dtype=np.float32, buffer=buffer))

    def close(self, worker: Worker) -> None:
        self.attach(worker, {})


def _context(preload: tuple[str, ...]):
    """The fork server where there is one (loading ``preload`` before it forks a worker), else spawn."""
    if "forkserver" not in mp.get_all_start_methods():
        return mp.get_context("spawn")
    context = mp.get_context("forkserver")
    # (the server starts with the first worker; a server this process already runs keeps its modules)
    context.set_forkserver_preload(["__main__", *preload])
    return context


class _Slot:
    """One worker process and what it is working on."""

    def __init__(self, process, conn):
        self.process, self.conn = process, conn
        self.chunk: collections.deque = collections.deque()  # task indices not yet reported


class ProcessEvaluator:
    def __init__(self, build_problem: Callable[[], object], noise: NoiseTable, dim: int,
                 env_ids: tuple[str, ...], workers: int, preload: tuple[str, ...] = ()):
        if noise.name is None:
            raise ValueError("the process pool needs a noise table in shared memory")
        check_workers(workers)
        self.env_ids, self.workers = env_ids, workers
        self._args = (build_problem, noise.name, noise.size)
        self._dim = dim
        self._theta_memory = shared_memory.SharedMemory(create=True, size=max(dim, 1) * 4)
        self._theta = np.ndarray((dim,), dtype=np.float32, buffer=self._theta_memory.buf)
        self._extras = SharedArrays()
        pin_threads()  # here, before the workers (and the fork server) start and load their libraries
        self._context = _context(preload)
        self._slots: list[_Slot] = []
        self._chunks = ChunkSizer(workers)
        try:
            for _ in range(workers):  # they start in parallel; each one kept at once, for close() to end it
                self._slots.append(self._spawn())
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

    def evaluate(self, generation: Generation, progress: Progress | None = None) -> Results:
        self._theta[:] = generation.theta
        extras = self._extras.publish(generation.extras())
        tasks = generation.tasks
        book = TaskBook(tasks, self.env_ids, progress)
        size = self._chunks.size(len(tasks))
        idle = list(self._slots)
        busy: dict = {}  # connection or process sentinel -> slot
        while book.remaining or busy:  # busy: wait for every "done", so no message is left over
            while idle and book.waiting:
                slot = idle.pop()
                slot.chunk = collections.deque(book.next_chunk(size))
                slot.conn.send((generation.number, generation.sigma, generation.statistics, extras,
                                tasks[list(slot.chunk)]))
                busy[slot.conn] = busy[slot.process.sentinel] = slot
            for ready in connection.wait(list(busy)):
                slot = busy.get(ready)
                if slot is None:  # handled already through its other handle
                    continue
                if self._receive(slot, book, block=ready is slot.conn):
                    del busy[slot.conn], busy[slot.process.sentinel]
                    idle.append(slot if slot.process.is_alive() and not slot.chunk else self._replace(slot, book))
        self._chunks.finished(len(tasks))
        return book.results

    def _receive(self, slot: _Slot, book: TaskBook, block: bool) -> bool:
        """Read what ``slot`` sent; True once it is finished with its chunk (or dead)."""
        try:
            while block or slot.conn.poll():
                block = False
                kind, payload = slot.conn.recv()
                if kind == "done":
                    return True
                book.record(slot.chunk.popleft(), kind, payload)
        except (EOFError, OSError):
            return True
        return not slot.process.is_alive()

    def _replace(self, slot: _Slot, book: TaskBook) -> _Slot:
        """Start a fresh worker for a dead one; its unfinished tasks go back in the queue."""
        slot.process.join(timeout=5)
        slot.conn.close()
        lost = list(slot.chunk)
        book.put_back(lost)
        fresh = self._spawn()
        self._await_ready(fresh)
        self._slots[self._slots.index(slot)] = fresh
        if lost:  # the first unreported task is the one it was running
            book.failed(lost[0], f"worker process died ({_describe_exit(slot.process)})")
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
        self._extras.close()
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
