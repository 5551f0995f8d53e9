"""Several runs per configuration, reported with honest statistics (Agarwal et al., NeurIPS 2021).

A *group* is a configuration (static or Hebbian, one strategy or another) and the run folders that
trained it on different seeds. Each run is reduced to one *score* (``SCORES``), and each group's
scores are summarised, through ``rliable`` (the authors' library), by:

- the interquartile mean (IQM: the mean of the middle 50 % of the runs, ``scipy.stats.trim_mean``
  at 25 %) and the mean, each with a stratified bootstrap confidence interval (percentile method);
- the performance profile: the fraction of runs scoring above each threshold τ, with its band;
- the probability of improvement P(X > Y) of every group over every other (the Mann-Whitney U
  statistic over the pairs of runs, ties counting one half), with its bootstrap interval.

Every bootstrap starts from ``--seed`` (``_seeded``), so a report is the same every time for a
fixed seed. A report compares runs of ONE task: rliable's aggregates over
several tasks need scores on a common scale, which raw returns of different environments are not.

The score of a run (``--score``):

- ``final`` (the default): the return of the final centre θ, from the last row of metrics.csv:
  ``center_eval_mean`` where the run evaluated its centre (``--eval_every``), else ``center_return``
  (one episode on a training seed);
- ``best``: the best such value over all generations (optimistic: a maximum over noisy values);
- ``evaluation``: the mean return in the run's ``evaluation.json`` (``evaluate_*.py --json``, as
  ``experiments/paper.py`` writes it: its final centre's); ``--environment`` picks one environment of several;
- ``evaluation_best``: the same in ``evaluation_best.json``, the evaluation of the run's best centre (the one
  with the best training return) that ``experiments/paper.py`` writes beside it.

``rliable`` is an optional extra (``pip install -r requirements-stats.txt``), imported only when the
statistics are computed.
"""

from __future__ import annotations

import csv
import functools
import glob
import io
import json
import math
import os
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from es import files

INSTALL_HINT = "pip install -r requirements-stats.txt"
DEFAULT_REPS = 2000
CONFIDENCE = 0.95


class StatsError(ValueError):
    """A group, run folder or score that cannot be reported; says which and what would be valid."""


def available() -> bool:
    try:
        import rliable  # noqa: F401
    except ImportError:
        return False
    return True


# --- the score of a run ---------------------------------------------------------------------------


def _centre_values(run_dir: Path) -> list[float]:
    """Per generation, the centre's return: its evaluation mean where there is one, else its episode."""
    path = run_dir / "metrics.csv"
    rows = files.read_metrics(path)
    if not rows:
        raise StatsError(f"{path} holds no generation yet; let the run finish one")

    def value(row: dict) -> float:
        evaluated = row.get("center_eval_mean") or ""
        return float(evaluated if evaluated and math.isfinite(float(evaluated)) else row["center_return"])
    try:
        return [value(row) for row in rows]
    except (KeyError, ValueError, TypeError) as error:
        raise StatsError(f"{path} is not a metrics file of this tool ({type(error).__name__}: {error})") from None


def final_score(run_dir: Path, environment: str | None = None) -> float:
    return _centre_values(run_dir)[-1]


def best_score(run_dir: Path, environment: str | None = None) -> float:
    return max(_centre_values(run_dir))


# the files of a run folder that score it, by score: what evaluate_*.py --json wrote, under the names
# experiments/paper.py gives them (the final centre's evaluation, the run's result, and the best centre's)
EVALUATIONS = {"evaluation": "evaluation.json", "evaluation_best": "evaluation_best.json"}


def evaluation_score(run_dir: Path, environment: str | None = None, score: str = "evaluation") -> float:
    """The mean return in the evaluation file of ``score`` (``EVALUATIONS``), over its episodes (of
    ``environment``, or of all its environments)."""
    path = run_dir / EVALUATIONS[score]
    if not path.is_file():
        raise StatsError(f"{run_dir}: no {path.name} (evaluate the run with evaluate_*.py --json "
                         f"{path}, or use --score final)")
    try:
        reports = files.read_json(path)["environments"]
        chosen = [report for report in reports if environment in (None, report["environment"])]
        if not chosen:
            found = ", ".join(report["environment"] for report in reports)
            raise StatsError(f"{path} has no environment {environment}; it has {found}")
        returns = [float(value) for report in chosen for value in report["returns"]]
    except (KeyError, TypeError, ValueError, json.JSONDecodeError) as error:
        if isinstance(error, StatsError):
            raise
        raise StatsError(f"{path} is not an evaluation file of this tool ({type(error).__name__})") from None
    return float(np.mean(returns))


SCORES: dict[str, Callable[[Path, str | None], float]] = {
    "final": final_score, "best": best_score,
    **{score: functools.partial(evaluation_score, score=score) for score in EVALUATIONS}}


# --- groups of run folders ------------------------------------------------------------------------


def run_folders(pattern: str) -> list[Path]:
    """The run folders a path or glob names: run folders themselves (with metrics.csv), or any folder
    holding run folders below it (a launch folder of ``experiments/seeds.py``)."""
    paths = sorted(Path(path) for path in glob.glob(pattern)) or ([Path(pattern)] if Path(pattern).exists() else [])
    found: list[Path] = []
    for path in paths:
        if (path / "metrics.csv").is_file():
            found.append(path)
        elif path.is_dir():
            found += sorted(metrics.parent for metrics in path.rglob("metrics.csv"))
    return found


def parse_group(text: str) -> tuple[str, list[str]]:
    """``NAME=PATTERN[,PATTERN...]``."""
    name, equals, patterns = text.partition("=")
    if not equals or not name.strip() or not patterns.strip():
        raise StatsError(f"--group {text!r}: give NAME=RUN_FOLDERS, e.g. --group static='runs/static/*'")
    return name.strip(), [pattern for pattern in patterns.split(",") if pattern]


def environment_of(run_dir: Path) -> str:
    """The run's environment label (config.json's env_ids, joined), to keep one task per report."""
    try:
        config = files.read_json(run_dir / "config.json")
        ids = config["env"]["env_ids"] if "env" in config else config["env_ids"]
        return ",".join(ids)
    except (OSError, KeyError, TypeError, ValueError):
        raise StatsError(f"{run_dir}: no readable config.json (not a run folder of this tool)") from None


def collect(groups: list[str], score: str, environment: str | None = None) -> dict[str, dict[Path, float]]:
    """Each group's runs and their scores; refuses empty groups, a run in two groups, and mixed tasks."""
    if score not in SCORES:
        raise StatsError(f"--score {score}: must be one of {', '.join(SCORES)}")
    scores: dict[str, dict[Path, float]] = {}
    seen: dict[Path, str] = {}
    for text in groups:
        name, patterns = parse_group(text)
        if name in scores:
            raise StatsError(f"--group {name} is given twice; give each group one name")
        runs = [run for pattern in patterns for run in run_folders(pattern)]
        if not runs:
            raise StatsError(f"--group {name}: no run folder (with a metrics.csv) matches {', '.join(patterns)}")
        for run in runs:
            if run.resolve() in seen:
                raise StatsError(f"{run} is in both groups {seen[run.resolve()]} and {name}")
            seen[run.resolve()] = name
        scores[name] = {run: SCORES[score](run, environment) for run in runs}
    if len(groups) == 0:
        raise StatsError("no --group given; give at least one, e.g. --group static='runs/static/*'")
    tasks = {environment_of(run) for runs in scores.values() for run in runs}
    if len(tasks) > 1 and score not in EVALUATIONS:
        raise StatsError(f"the runs are on different environments ({', '.join(sorted(tasks))}); report one "
                         "environment at a time")
    return scores


# --- the statistics -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Summary:
    group: str
    runs: int
    iqm: float
    iqm_low: float
    iqm_high: float
    mean: float
    mean_low: float
    mean_high: float
    median: float


@dataclass(frozen=True)
class Improvement:
    x: str
    y: str
    probability: float  # P(X > Y)
    low: float
    high: float


def _column(values) -> np.ndarray:
    """rliable's layout: runs × tasks (one task)."""
    return np.asarray(list(values), dtype=np.float64).reshape(-1, 1)


def _seeded(seed: int, call, *args, **kwargs):
    """``call`` with numpy's global generator seeded, and restored afterwards.

    rliable 1.2.0's stratified bootstraps draw their indices from ``np.random.choice`` (the global
    generator) whatever ``random_state`` they are given, so a fixed seed is set there for the call; the
    RandomState is passed too (arch's own draws), through arch's deprecated keyword, hence the filter."""
    saved = np.random.get_state()
    np.random.seed(seed)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)
            return call(*args, random_state=np.random.RandomState(seed), **kwargs)
    finally:
        np.random.set_state(saved)


def summarise(scores: dict[str, list[float]], reps: int = DEFAULT_REPS, seed: int = 0) -> list[Summary]:
    """IQM and mean of each group with their stratified bootstrap 95 % intervals."""
    from rliable import library, metrics

    def aggregates(matrix: np.ndarray) -> np.ndarray:
        return np.array([metrics.aggregate_iqm(matrix), metrics.aggregate_mean(matrix)])
    summaries = []
    for name, values in scores.items():
        matrix = _column(values)
        points, intervals = _seeded(seed, library.get_interval_estimates, {name: matrix}, aggregates, reps=reps,
                                   confidence_interval_size=CONFIDENCE)
        (iqm, mean), ((iqm_low, mean_low), (iqm_high, mean_high)) = points[name], intervals[name]
        summaries.append(Summary(name, len(matrix), float(iqm), float(iqm_low), float(iqm_high), float(mean),
                                 float(mean_low), float(mean_high), float(np.median(matrix))))
    return summaries


def improvements(scores: dict[str, list[float]], reps: int = DEFAULT_REPS, seed: int = 0) -> list[Improvement]:
    """P(X > Y) for every ordered pair of groups, with its bootstrap interval (runs resampled in each)."""
    from rliable import library, metrics

    found = []
    for x, x_scores in scores.items():
        for y, y_scores in scores.items():
            if x == y:
                continue
            pair = [_column(x_scores), _column(y_scores)]
            points, intervals = _seeded(seed, library.get_interval_estimates, {"pair": pair},
                                       metrics.probability_of_improvement, reps=reps,
                                       confidence_interval_size=CONFIDENCE)
            low, high = np.ravel(intervals["pair"])
            found.append(Improvement(x, y, float(points["pair"]), float(low), float(high)))
    return found


def thresholds(scores: dict[str, list[float]], count: int = 41) -> np.ndarray:
    values = np.concatenate([np.asarray(v, dtype=np.float64) for v in scores.values()])
    low, high = float(values.min()), float(values.max())
    return np.linspace(low - 1e-9 * max(1.0, abs(low)), high, count) if high > low else np.array([low - 1, low])


def profiles(scores: dict[str, list[float]], taus: np.ndarray, reps: int = DEFAULT_REPS,
             seed: int = 0) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The performance profile (fraction of runs scoring above τ) of each group, with its band.

    rliable's ``create_performance_profile`` takes no random state, so its profile function is given to
    ``get_interval_estimates`` here, seeded like the rest."""
    from rliable import library

    def profile(matrix: np.ndarray) -> np.ndarray:
        return (matrix[..., None] > taus).mean(axis=(0, 1))
    found = {}
    for name, values in scores.items():
        points, intervals = _seeded(seed, library.get_interval_estimates, {name: _column(values)}, profile, reps=reps,
                                   confidence_interval_size=CONFIDENCE)
        found[name] = (points[name], intervals[name][0], intervals[name][1])
    return found


# --- outputs --------------------------------------------------------------------------------------


NO_INTERVAL = "(no interval: 1 run)"


def markdown(summaries: list[Summary], pairs: list[Improvement], score: str) -> str:
    """The summary table and the pairs' table. A group of one run has no interval: every bootstrap resample of
    it is that run again, so the interval rliable returns is the point itself, and the table says so instead;
    so does a pair with such a group on either side."""
    runs = {s.group: s.runs for s in summaries}

    def interval(low: float, high: float, count: int, digits: int) -> str:
        return f"[{low:.{digits}f}, {high:.{digits}f}]" if count > 1 else NO_INTERVAL

    lines = ["| group | runs | IQM (95 % CI) | mean (95 % CI) | median |", "|---|---|---|---|---|"]
    lines += [f"| {s.group} | {s.runs} | {s.iqm:.1f} {interval(s.iqm_low, s.iqm_high, s.runs, 1)} | "
              f"{s.mean:.1f} {interval(s.mean_low, s.mean_high, s.runs, 1)} | {s.median:.1f} |" for s in summaries]
    if pairs:
        lines += ["", "| X | Y | P(X > Y) (95 % CI) |", "|---|---|---|"]
        lines += [f"| {p.x} | {p.y} | {p.probability:.2f} "
                  f"{interval(p.low, p.high, min(runs[p.x], runs[p.y]), 2)} |" for p in pairs]
    text = "\n".join(lines) + f"\n\nScore of a run: {score} (report/stats.py).\n"
    single = [s.group for s in summaries if s.runs == 1]
    if single:
        text += (f"\n{', '.join(single)}: one run, so no interval, and a probability of improvement against it "
                 f"compares single runs; train more seeds before reading a difference from this report.\n")
    return text


def csv_text(rows: list[dict]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue()


def figure(summaries: list[Summary], curves: dict, taus: np.ndarray, pairs: list[Improvement]):
    """Three panels: IQM and mean with their intervals, performance profiles, probabilities of improvement.

    Groups often tie (several strategies ending every run at CartPole's 500), so each profile has its own
    colour, line style and marker, the markers of group k at every k-th τ from its own offset: curves that
    coincide stay told apart. The constrained layout gives each panel the room its labels need, no more."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(14, 3.8), dpi=100, layout="constrained")
    FigureCanvasAgg(figure)
    left, middle, right = figure.subplots(1, 3, width_ratios=(1, 1.2, 1))
    styles, markers = ("-", "--", "-.", ":"), ("o", "s", "^", "D", "v", "P", "X", "*")
    for row, summary in enumerate(summaries):
        colour = f"C{row % 10}"
        estimates = ((summary.iqm, summary.iqm_low, summary.iqm_high, "o"),
                     (summary.mean, summary.mean_low, summary.mean_high, "s"))
        for offset, (point, low, high, marker) in enumerate(estimates):
            left.errorbar([point], [row + 0.15 - 0.3 * offset], xerr=[[point - low], [high - point]], fmt=marker,
                          color=colour, capsize=3, label=("IQM" if offset == 0 else "mean") if row == 0 else None)
        fraction, low, high = curves[summary.group]
        middle.plot(taus, fraction, color=colour, label=summary.group, linestyle=styles[row % len(styles)],
                    marker=markers[row % len(markers)], markevery=(row % len(summaries), len(summaries)),
                    markersize=5)
        middle.fill_between(taus, low, high, color=colour, alpha=0.2, linewidth=0)
    left.set_yticks(range(len(summaries)), [summary.group for summary in summaries])
    left.set_title("IQM (o) and mean (s), 95 % CI", fontsize=10)
    left.set_xlabel("score")
    middle.set_title("performance profile", fontsize=10)
    middle.set_xlabel("score τ")
    middle.set_ylabel("fraction of runs > τ")
    middle.legend(fontsize=8, frameon=False)
    for row, pair in enumerate(pairs):
        right.errorbar([pair.probability], [row], xerr=[[pair.probability - pair.low], [pair.high - pair.probability]],
                       fmt="o", color="C0", capsize=3)
    right.axvline(0.5, color="grey", linestyle=":")
    right.set_xlim(0, 1)
    right.set_yticks(range(len(pairs)), [f"P({pair.x} > {pair.y})" for pair in pairs], fontsize=8)
    right.set_title("probability of improvement, 95 % CI", fontsize=10)
    for axes in (left, middle, right):
        axes.grid(alpha=0.3)
    return figure


@dataclass(frozen=True)
class Report:
    summaries: list[Summary]
    improvements: list[Improvement]
    scores: dict[str, dict[Path, float]]
    markdown: str


def report(groups: list[str], out: Path, score: str = "final", environment: str | None = None,
           reps: int = DEFAULT_REPS, seed: int = 0, root: Path | None = None) -> Report:
    """Compute everything and write ``summary.md``, ``summary.csv``, ``improvement.csv``,
    ``scores.csv`` and ``report.png`` in ``out``; ``scores.csv`` names each run as its group gave it, or
    relative to ``root`` (a report committed beside its runs, read on any machine)."""
    from report.plots import write_figure

    per_run = collect(groups, score, environment)
    scores = {name: list(runs.values()) for name, runs in per_run.items()}
    summaries = summarise(scores, reps, seed)
    pairs = improvements(scores, reps, seed)
    taus = thresholds(scores)
    curves = profiles(scores, taus, reps, seed)
    text = markdown(summaries, pairs, score)
    out.mkdir(parents=True, exist_ok=True)
    files.atomic_write_text(out / "summary.md", text)
    files.atomic_write_text(out / "summary.csv", csv_text([asdict(summary) for summary in summaries]))
    if pairs:
        files.atomic_write_text(out / "improvement.csv", csv_text([asdict(pair) for pair in pairs]))

    def named(run: Path) -> str:
        return str(run) if root is None else Path(os.path.relpath(run, root)).as_posix()

    files.atomic_write_text(out / "scores.csv", csv_text([{"group": name, "run": named(run), "score": value}
                                                           for name, runs in per_run.items()
                                                           for run, value in runs.items()]))
    write_figure(figure(summaries, curves, taus, pairs), out / "report.png", bbox_inches="tight")
    return Report(summaries, pairs, per_run, text)
