"""The live progress line of a run: what a generation is doing while it runs.

On a terminal, a tqdm bar during every generation shows the episodes done out of the total, the
env steps per second, and the ETA of the generation and of the whole run; the bar is cleared when
the generation ends, leaving only the run's one line per generation. When stdout is not a terminal
(CI, ``nohup``, a file) nothing is drawn, so the output stays exactly one line per generation.

A display's ``generation(...)`` context yields the ``progress(n_done, steps)`` callback that the
backends accept (``es.backends``), or None when there is nothing to show.
"""

from __future__ import annotations

import contextlib
import shutil
import sys
import time
from collections.abc import Iterator
from contextlib import AbstractContextManager
from typing import Protocol, TextIO

from tqdm import tqdm

from es.backends import Progress as Callback  # (episodes just finished, their env steps)

RECENT_GENERATIONS = 5  # the run ETA assumes the coming generations take as long as these did


class Display(Protocol):
    def generation(self, number: int, episodes: int, generations_after: int) -> AbstractContextManager[Callback | None]:
        """Around generation ``number`` of ``episodes`` episodes: yields the evaluators' callback."""


class QuietDisplay:
    """No live output: the run's per-generation log line is all there is."""

    @contextlib.contextmanager
    def generation(self, number: int, episodes: int, generations_after: int) -> Iterator[Callback | None]:
        yield None


def estimate(done: int, total: int, elapsed: float, generations_after: int,
             recent: list[float]) -> tuple[float, float]:
    """(seconds left in this generation, seconds left in the run), NaN while nothing is known.

    The coming generations are assumed to take as long as the recent ones did on average, or,
    before any has finished, as long as this one is projected to take.
    """
    if done == 0:
        return float("nan"), float("nan")
    projected = elapsed * total / done
    typical = sum(recent) / len(recent) if recent else projected
    left = projected - elapsed
    return left, left + generations_after * typical


def _clock(seconds: float) -> str:
    return "?" if seconds != seconds else tqdm.format_interval(seconds)  # NaN != NaN


class LiveDisplay:
    """A tqdm bar per generation, written to ``stream`` (the terminal the log goes to)."""

    BAR_FORMAT = "{desc} |{bar}| {n_fmt}/{total_fmt} episodes{postfix}"  # tqdm puts ", " before a postfix

    def __init__(self, stream: TextIO):
        self.stream = stream
        self.recent: list[float] = []  # seconds of the last few generations

    @contextlib.contextmanager
    def generation(self, number: int, episodes: int, generations_after: int) -> Iterator[Callback]:
        width = shutil.get_terminal_size(fallback=(100, 24)).columns  # read per generation: resizes apply
        bar = tqdm(total=episodes, desc=f"generation {number}", file=self.stream, leave=False, ncols=width,
                   bar_format=self.BAR_FORMAT)
        started = time.perf_counter()
        steps = 0

        def progress(n_done: int, episode_steps: int) -> None:
            nonlocal steps
            steps += episode_steps
            elapsed = time.perf_counter() - started
            left, run_left = estimate(bar.n + n_done, episodes, elapsed, generations_after, self.recent)
            bar.set_postfix_str(f"{steps / max(elapsed, 1e-9):,.0f} steps/s | generation ETA {_clock(left)} "
                                f"| run ETA {_clock(run_left)}", refresh=False)
            bar.update(n_done)

        try:
            yield progress
        finally:
            bar.close()
        self.recent = (self.recent + [time.perf_counter() - started])[-RECENT_GENERATIONS:]


def display_for(stream: TextIO = sys.stdout) -> Display:
    """A live bar when ``stream`` is a terminal, nothing otherwise."""
    try:
        terminal = stream.isatty()
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        terminal = False
    return LiveDisplay(stream) if terminal else QuietDisplay()
