"""Learning curves from ``metrics.csv``: a run's own ``fitness.png``, and several runs overlaid.

Fitness is what the strategy ranks: the mean episode return minus the L2 penalty (``es.shaping``).
One run's picture shows, per generation, the population's mean, the band between its min and
max, the best fitness seen so far, the return of the unperturbed centre theta, and, with
``--eval_every``, the centre's evaluation mean with a band of one standard deviation (which then
picks ``best.dat``). The comparison overlays the mean and best-so-far of several runs. Columns a
metrics.csv of an earlier version lacks, or a generation left empty, read as NaN.

Drawing uses matplotlib's Agg canvas directly (no pyplot, so no global state and no display), and
the picture is written atomically like every other file of a run, in the format its suffix names.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from es import files

WIDTH, HEIGHT, DPI = 8, 4.5, 100


def curves(rows: Sequence[dict]) -> dict[str, np.ndarray]:
    """Columns of metrics rows (as written, or as read back from the CSV) as float arrays."""
    def column(name: str) -> np.ndarray:
        return np.array([float(row.get(name) or "nan") for row in rows], dtype=np.float64)

    maximum = column("fitness_max")
    return {"generation": column("generation"), "mean": column("fitness_mean"), "max": maximum,
            "min": column("fitness_min"), "center": column("center_return"),
            "eval_mean": column("center_eval_mean"), "eval_std": column("center_eval_std"),
            "best": np.fmax.accumulate(maximum) if maximum.size else maximum}  # fmax skips NaN


def _figure(title: str):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    figure = Figure(figsize=(WIDTH, HEIGHT), dpi=DPI)
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    axes.set_title(title, fontsize=10)
    axes.set_xlabel("generation")
    axes.xaxis.set_major_locator(MaxNLocator(integer=True))  # generations are whole numbers
    axes.set_ylabel("fitness")
    axes.grid(alpha=0.3)
    return figure, axes


def _legend_outside(axes) -> None:
    """To the right of the axes, where it never hides a curve."""
    axes.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)


def run_figure(rows: Sequence[dict], title: str):
    """One run: mean, min-max band, best so far, centre return."""
    figure, axes = _figure(title)
    data = curves(rows)
    x = data["generation"]
    axes.fill_between(x, data["min"], data["max"], color="C0", alpha=0.2, linewidth=0,
                      label="population min-max")
    axes.plot(x, data["mean"], color="C0", label="population mean")
    axes.plot(x, data["best"], color="C3", linestyle="--", label="best so far")
    axes.plot(x, data["center"], color="C2", linestyle=":", label="centre return")
    evaluated = np.isfinite(data["eval_mean"])
    if evaluated.any():
        mean, std = data["eval_mean"][evaluated], data["eval_std"][evaluated]
        axes.fill_between(x[evaluated], mean - std, mean + std, color="C1", alpha=0.25, linewidth=0)
        axes.plot(x[evaluated], mean, color="C1", marker=".", label="centre evaluation mean ± std")
    _legend_outside(axes)
    return figure


def comparison_figure(runs: Sequence[tuple[str, Sequence[dict]]], generations: int | None = None):
    """Several runs: each one's population mean (solid), centre return (dotted) and best so far (dashed) in its
    own colour; given ``generations``, the x axis reaches that far, so that a run not yet complete shows where
    it stands."""
    figure, axes = _figure("population mean (solid), centre (dotted), best so far (dashed)")
    if generations is not None:
        axes.set_xlim(0, generations)
    for number, (label, rows) in enumerate(runs):
        data, colour = curves(rows), f"C{number % 10}"
        axes.plot(data["generation"], data["mean"], color=colour, label=label)
        axes.plot(data["generation"], data["center"], color=colour, linestyle=":", linewidth=1)
        axes.plot(data["generation"], data["best"], color=colour, linestyle="--")
    _legend_outside(axes)
    return figure


FIGURE_SUFFIXES = (".png", ".pdf", ".svg")  # the formats a figure is written in, named by the file's suffix


def write_figure(figure, path: Path, **options) -> None:
    """The figure, in the format its suffix names (one of FIGURE_SUFFIXES), written atomically."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in FIGURE_SUFFIXES:
        raise ValueError(f"{path}: a figure is written as {', '.join(FIGURE_SUFFIXES)}, named by its suffix")
    buffer = io.BytesIO()
    figure.savefig(buffer, format=suffix[1:], **options)
    files.atomic_write_bytes(path, buffer.getvalue())


def save_run_plot(path: Path, rows: Sequence[dict], title: str) -> None:
    """Write one run's learning curve to ``path`` (its ``fitness.png``)."""
    write_figure(run_figure(rows, title), path, bbox_inches="tight")


def save_comparison(path: Path, runs: Sequence[tuple[str, Sequence[dict]]], generations: int | None = None) -> None:
    """Overlay several runs, given as (label, metrics rows), in one picture at ``path`` (``comparison_figure``)."""
    write_figure(comparison_figure(runs, generations), path, bbox_inches="tight")
