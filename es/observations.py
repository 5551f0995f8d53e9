"""Running observation statistics for ``--obs_norm`` (OpenAI's ``RunningStat``), and their files.

Salimans et al. (2017) normalise the observations a network sees by a running mean and standard
deviation (openai/evolution-strategies-starter, ``es_distributed/es.py``; docs/original.md, "The
evolution strategy"). As there:

- the statistics are sums: ``sum``, ``sumsq`` (starting at ``EPS``) and ``count`` (starting at ``EPS``,
  1e-2, so that with no data mean = 0 and std = 1: the identity);
- mean = sum / count and std = sqrt(max(sumsq / count - mean^2, STD_FLOOR^2)), floored at 0.1;
- a fraction (``--obs_norm_prob``, es-starter's ``calc_obstat_prob``, 0.01) of the episodes add
  the observations their policy acted on; both members of a mirrored pair do or neither does;
- they are frozen within a generation: the statistics a generation's episodes use are published
  with theta, and the sums those episodes return are added when the generation is over.

The runner adds the sums in task order (member order), whatever order the workers finished in, so
a run gives the same theta with any number of workers and with Ray. Everything is float64.

Where the normalisation happens is ``policies.normalised``. Beside every weight file a run saves,
``<name>.obs_norm.npz`` holds the statistics that file was (or will next be) evaluated with;
``evaluate_*.py`` reads it (``np.load`` without pickle).
"""

from __future__ import annotations

import io
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

EPS = 1e-2  # es-starter: RunningStat(shape, eps=1e-2)
STD_FLOOR = 0.1  # es-starter: sqrt(maximum(var, 1e-2))
SUFFIX = ".obs_norm.npz"

ObservationSums = tuple[np.ndarray, np.ndarray, int]  # (sum, sum of squares, count) of one episode


@dataclass(frozen=True)
class RunningStat:
    sum: np.ndarray  # float64
    sumsq: np.ndarray  # float64
    count: float

    @classmethod
    def empty(cls, size: int) -> RunningStat:
        return cls(np.zeros(size), np.full(size, EPS), EPS)

    def merged(self, episodes: Iterable[ObservationSums | None]) -> RunningStat:
        """These statistics plus each episode's sums, in the order given (None: did not record)."""
        total, squares, count = self.sum.copy(), self.sumsq.copy(), self.count
        for sums in episodes:
            if sums is not None:
                total += sums[0]
                squares += sums[1]
                count += sums[2]
        return RunningStat(total, squares, count)

    @property
    def mean(self) -> np.ndarray:
        return self.sum / self.count

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.maximum(self.sumsq / self.count - np.square(self.mean), STD_FLOOR ** 2))

    @property
    def observations(self) -> int:
        """How many observations were added (the count without its EPS prior)."""
        return int(round(self.count - EPS))

    def published(self) -> tuple[np.ndarray, np.ndarray]:
        """(mean, std): what the workers' policies normalise with."""
        return self.mean, self.std

    def to_arrays(self) -> dict[str, np.ndarray]:
        return {"sum": self.sum, "sumsq": self.sumsq, "count": np.array(self.count)}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> RunningStat | None:
        if not arrays:
            return None
        return cls(np.asarray(arrays["sum"], np.float64), np.asarray(arrays["sumsq"], np.float64),
                   float(arrays["count"]))


# --- the file beside a weight file -------------------------------------------------------------


def statistics_path(weight_file: str | Path) -> Path:
    """``run/last.dat`` -> ``run/last.obs_norm.npz``."""
    weight_file = Path(weight_file)
    return weight_file.with_name(weight_file.stem + SUFFIX)


def statistics_bytes(stat: RunningStat, clip: float | None) -> bytes:
    """The file's content: mean, std, clip (inf: none) and the number of observations behind them."""
    buffer = io.BytesIO()
    np.savez(buffer, mean=stat.mean, std=stat.std, clip=np.array(np.inf if clip is None else clip),
             observations=np.array(stat.observations))
    return buffer.getvalue()


@dataclass(frozen=True)
class SavedStatistics:
    mean: np.ndarray
    std: np.ndarray
    clip: float | None
    observations: int


def load_statistics(path: str | Path) -> SavedStatistics:
    """A statistics file, read without pickle; a ValueError names a file that is not one."""
    try:
        with np.load(path, allow_pickle=False) as saved:
            clip = float(saved["clip"])
            loaded = SavedStatistics(np.asarray(saved["mean"], np.float64), np.asarray(saved["std"], np.float64),
                                     clip if np.isfinite(clip) else None, int(saved["observations"]))
    except Exception as error:
        raise ValueError(f"cannot read observation statistics {path}: {type(error).__name__}: {error}") from None
    if (loaded.mean.shape != loaded.std.shape or loaded.mean.ndim != 1 or not (loaded.std > 0).all()
            or not np.isfinite(loaded.mean).all() or not np.isfinite(loaded.std).all()):
        raise ValueError(f"{path} is not an observation statistics file (finite mean and std of one shape, std > 0)")
    return loaded
