"""The shared noise table (Salimans et al. 2017, as in openai/evolution-strategies-starter).

One float32 table of N(0, 1) samples, made once per run from the run's seed. A perturbation is
the slice ``table[index : index + dim]``, so only indices travel between processes. The table lives
in ``multiprocessing.shared_memory`` when workers need it: every worker maps the same pages.
"""

from __future__ import annotations

from multiprocessing import shared_memory

import numpy as np

MIN_SIZE = 1 << 22  # 16 MB
MAX_SIZE = 1 << 25  # 128 MB


def default_size(dim: int) -> int:
    """Room for many distinct slices of length ``dim``, within a budget fit for a laptop."""
    return int(min(max(64 * dim, MIN_SIZE), MAX_SIZE))


def attach_shared(name: str) -> shared_memory.SharedMemory:
    """Map a segment another process created.

    Workers share the creator's resource tracker (forkserver and spawn pass it on), so the
    registration Python < 3.13 makes here is the creator's own and its unlink clears it.
    """
    return shared_memory.SharedMemory(name=name)


class NoiseTable:
    def __init__(self, array: np.ndarray, memory: shared_memory.SharedMemory | None = None,
                 owner: bool = False):
        self.array = array
        self._memory = memory
        self._owner = owner

    @classmethod
    def create(cls, seed: int, size: int, shared: bool = False) -> NoiseTable:
        if not shared:
            array = np.empty(size, dtype=np.float32)
            np.random.default_rng(seed).standard_normal(size, dtype=np.float32, out=array)
            return cls(array)
        table = cls(np.empty(0, np.float32), shared_memory.SharedMemory(create=True, size=size * 4), owner=True)
        try:  # a failure or Ctrl-C while filling it must not leave the segment behind
            table.array = np.ndarray((size,), dtype=np.float32, buffer=table._memory.buf)
            np.random.default_rng(seed).standard_normal(size, dtype=np.float32, out=table.array)
        except BaseException:
            table.close()
            raise
        return table

    @classmethod
    def attach(cls, name: str, size: int) -> NoiseTable:
        memory = attach_shared(name)
        return cls(np.ndarray((size,), dtype=np.float32, buffer=memory.buf), memory)

    @property
    def size(self) -> int:
        return self.array.size

    @property
    def name(self) -> str | None:
        return self._memory.name if self._memory is not None else None

    def sample_indices(self, rng: np.random.Generator, dim: int, count: int) -> np.ndarray:
        if dim > self.size:
            raise ValueError(f"noise table of {self.size} values is smaller than the {dim} parameters")
        return rng.integers(0, self.size - dim + 1, size=count, dtype=np.int64)

    def slice(self, index: int, dim: int) -> np.ndarray:
        return self.array[index:index + dim]

    def close(self) -> None:
        if self._memory is None:
            return
        self.array = np.empty(0, dtype=np.float32)  # drop the view before unmapping
        self._memory.close()
        if self._owner:
            self._memory.unlink()
        self._memory = None
