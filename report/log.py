"""What a training run shows and draws as it goes: its one line per generation, and ``fitness.png``.

The training script makes them and hands them what the generation loop hands it (``es.loop.GenerationRecord``):
each generation's metrics row, and each save; the loop itself never prints.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from es.runfolder import SaveError
from report.plots import save_run_plot


def generation_line(row: dict) -> str:
    """The original's line (iter, reward, update_factor, lr, sum and sum of |.| of the penalised
    parameters: weights or Hebbian coefficients), then the centre's return and rank among the
    N + 1 (pytorch-es's "unperturbed rank": 1 of N + 1 means no member beat the centre, an
    uninformative gradient; ``--eval_every`` generations: its evaluation mean ± std too), env steps
    and seconds, the episode cap of ``--variable_ep_len``, and the centre's evolved reservoir
    (``--reservoir_evolve``)."""
    name = row["parameters_name"]
    evaluation = (f" | eval: {row['center_eval_mean']:.2f} ± {row['center_eval_std']:.2f}"
                  if row["center_eval_mean"] == row["center_eval_mean"] else "")  # NaN: not evaluated
    line = (f"iter {row['generation']} | reward: {row['fitness_mean']:.3f} | "
            f"update_factor: {row['update_factor']:.6f} | lr: {row['lr']:g} | "
            f"sum_{name}: {row['parameters_sum']:.3f} | sum_abs_{name}: {row['parameters_abs_sum']:.3f} | "
            f"center: {row['center_return']:.2f} (rank {row['center_rank']} of {row['population'] + 1})"
            f"{evaluation} | "
            f"steps: {row['env_steps']} | {row['seconds']:.1f}s")
    if row["nonfinite"]:
        line += f" | {row['nonfinite']} non-finite returns ranked last"
    if row["episode_cap"]:
        line += f" | episodes capped at {row['episode_cap']} steps"
    if "reservoir_lr" in row:
        line += (f" | reservoir: lr {row['reservoir_lr']:.4g}, sr {row['reservoir_sr']:.4g}, "
                 f"iss {row['reservoir_iss']:.4g}")
    if row["skipped"]:
        line += " | step skipped: all fitness values equal"
    return line


class GenerationLog:
    """Prints one line per generation."""

    def __init__(self, log: Callable[[str], None] = print):
        self.log = log

    def generation(self, row: dict) -> None:
        self.log(generation_line(row))


class FitnessPlot:
    """Draws the run's ``fitness.png``: at a save once ``redraw_seconds`` have passed since it last drew (or since
    the run began), and when the run ends, with every row saved. A drawing costs a good part of a second, the first
    one more (matplotlib's import): drawn at every save, a run of short generations spent a sizeable share of its
    time drawing pictures nobody looked at before the next one."""

    def __init__(self, redraw_seconds: float = 30.0, clock: Callable[[], float] = time.monotonic):
        self.redraw_seconds, self.clock = redraw_seconds, clock
        self.drawn_at = clock()
        self.pending: tuple[object, list[dict]] | None = None  # the folder and rows of a save not drawn yet

    def saved(self, folder, rows: list[dict]) -> None:
        self.pending = (folder, list(rows))
        if self.clock() - self.drawn_at >= self.redraw_seconds:
            self.draw()

    def finished(self, folder) -> None:
        self.draw()  # before the loggers send the run's figures

    def close(self) -> None:
        try:
            self.draw()
        except SaveError:  # a run stopping on a full disk: its data are saved, the picture is not worth a traceback
            pass

    def draw(self) -> None:
        if self.pending is not None:
            folder, rows = self.pending
            folder.write(save_run_plot, "fitness.png", rows, folder.name)
            self.pending, self.drawn_at = None, self.clock()
