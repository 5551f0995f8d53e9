"""The serial backend: every task in this process (``--threads 1``, tests)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from es.backends.base import Generation, Progress, Results, TaskBook
from es.noise import NoiseTable
from es.worker import Worker


class SerialEvaluator:
    def __init__(self, build_problem: Callable[[], object], noise: NoiseTable, dim: int,
                 env_ids: tuple[str, ...]):
        self.env_ids = env_ids
        self._theta = np.zeros(dim, dtype=np.float32)
        self._worker = Worker(build_problem, noise, self._theta)
        self.workers = 1

    def evaluate(self, generation: Generation, progress: Progress | None = None) -> Results:
        self._theta[:] = generation.theta
        extras = generation.extras()
        self._worker.scale, self._worker.rows = extras.get("scale"), extras.get("rows")
        book = TaskBook(generation.tasks, self.env_ids, progress)
        while book.waiting:
            index = book.waiting.popleft()
            book.record(index, *self._worker.run(generation.number, generation.sigma, generation.tasks[index],
                                                 generation.statistics))
        return book.results

    def close(self) -> None:
        self._worker.close()
