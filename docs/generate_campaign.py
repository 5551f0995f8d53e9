"""The docs' campaign results from a run's training and the campaign's plan (``results/paper/``; docs/generate.py).

How a run trained (``curve``), its frames (``frames``), what it adds to a clone (``weight``), an experiment's
report over its seeds (``report``) and the campaign's remaining runs with what they will cost (``remaining``),
each read from the runs' own files; a run's evaluation is ``generate_evaluations.py``'s. Until a run is evaluated
(or every run a report needs is in) the marker holds its pending text.
"""

from __future__ import annotations

import csv
from pathlib import Path

from generate_evaluations import PENDING, RUNS, evaluated, link
from generate_records import FigureError, listed, number

from cli.errors import USER_ERRORS
from experiments import campaign, cost
from experiments.paper_args import campaign_entries
from experiments.paper_report import report_folder
from experiments.paper_runs import load_experiment, run_name
from experiments.paper_status import campaign_plan

FRAMES_PENDING = "(the agent's frames, once its run is evaluated)"

REPORT_PENDING = "not yet: the campaign's seeds are still training"

KIND_NAMES = {"hebbian": "Hebbian", "static": "static"}

LAST_GENERATIONS = 50  # the stretch of a run's end a curve marker sums up


def curve(name: str, thresholds: list[str], page: Path, runs: Path = RUNS) -> str:
    """How a completed campaign run's training went, from its ``metrics.csv``: the first generation at which the
    population's mean return (``return_mean``) passed each threshold, and its range and the centre's training
    episodes' over the last 50 generations: "the population's mean return passed 100 at generation 96 and 500 at
    generation 146, and stayed between 528 and 664 over the last 50 generations, while the centre's own training
    episode scored 137 to 893 in them"."""
    run = evaluated(name, runs)
    if run is None:
        return PENDING
    try:
        levels = [float(word) for word in thresholds]
    except ValueError:
        raise FigureError(f"<!-- curve:{name} {' '.join(thresholds)} --> is not a marker: its thresholds are "
                          "numbers") from None
    try:
        rows = read_rows(run / "metrics.csv")
        means = [(int(row["generation"]), float(row["return_mean"])) for row in rows]
        last = rows[-LAST_GENERATIONS:]
        population = [float(row["return_mean"]) for row in last]
        centre = [float(row["center_return"]) for row in last]
    except (OSError, KeyError, ValueError) as error:
        raise FigureError(f"{name}: {run / 'metrics.csv'} holds no training curve ({type(error).__name__}: "
                          f"{error})") from None
    passed = []
    for word, level in zip(thresholds, levels, strict=True):
        generation = next((generation for generation, mean in means if mean > level), None)
        passed.append(f"{word} at generation {generation}" if generation is not None else f"never {word}")
    return (f"the population's mean return passed {listed(passed)}, and stayed between {number(min(population))} and "
            f"{number(max(population))} over the last {len(last)} generations, while the centre's own training "
            f"episode scored {number(min(centre))} to {number(max(centre))} in them")


def frames(name: str, page: Path, runs: Path = RUNS) -> str:
    run = evaluated(name, runs)
    if run is None or not (run / "frames.png").is_file():
        return FRAMES_PENDING
    return f"![{name}: every 100th frame of its first evaluation episode]({link(run / 'frames.png', page)})"


def weight(name: str, page: Path, runs: Path = RUNS) -> str:
    """What a campaign run adds to a clone, from its evaluated run folder's files: "each chunk commits its
    checkpoint.npz (3.6 MB); completed, the run adds its final weights (2.7 MB) and its evaluations and pictures
    (0.2 MB)"."""
    run = evaluated(name, runs)
    if run is None:
        return PENDING

    def size(paths) -> str:
        return f"{sum(path.stat().st_size for path in paths) / 1e6:.1f} MB"

    kept = [run / file for file in campaign.KEPT if (run / file).is_file()]
    pictures = [path for path in kept if path.name not in ("checkpoint.npz", "config.json", "metrics.csv")]
    return (f"each chunk commits its [checkpoint.npz]({link(run / 'checkpoint.npz', page)}) "
            f"({size([run / 'checkpoint.npz'])}) beside its config.json and metrics.csv; completed, the run adds its "
            f"final weights ({size(run.glob(campaign.FINAL_WEIGHTS))}) and its evaluations and pictures "
            f"({size(pictures)})")


def campaign_folders(experiment: str) -> dict[str, set[str]]:
    """Per kind, the folders of the runs experiments/paper/campaign.toml plans for ``experiment``."""
    planned: dict[str, set[str]] = {}
    for entry in campaign_entries():
        if entry.experiment == experiment:
            planned.setdefault(entry.kind, set()).add(run_name(entry, load_experiment(entry)[1]))
    return planned


def read_rows(path: Path) -> list[dict]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def report(experiment: str, environment: str, page: Path, runs: Path = RUNS,
           planned: dict[str, set[str]] | None = None) -> str:
    """The campaign's report of ``experiment`` on ``environment`` (``experiments/paper.py EXPERIMENT report``, in
    ``runs``): each kind's IQM and mean with their 95 % bootstrap intervals, and P(Hebbian > static), linked to
    the report, and how many of the runs the campaign plans for the experiment (``planned``: folder names per
    kind) are still to come. Pending until each kind has an evaluated run and the report holds every evaluated
    one, so that a page never shows a report older than the runs."""
    folder = report_folder(runs, experiment) / environment
    planned = campaign_folders(experiment) if planned is None else planned
    try:
        scores = read_rows(folder / "scores.csv")
        summaries = read_rows(folder / "summary.csv")
        pairs = read_rows(folder / "improvement.csv")
        reported = {Path(row["run"]).parts[0] for row in scores}  # the runs' folders: carracing_static_seed1, ...
    except FileNotFoundError:
        return REPORT_PENDING
    except (KeyError, IndexError):
        raise FigureError(f"{experiment}: {folder / 'scores.csv'} names no runs") from None
    done = {kind: {name for name in names if evaluated(name, runs)} for kind, names in planned.items()}
    if not planned or not all(done.values()) or not all(names <= reported for names in done.values()):
        return REPORT_PENDING
    to_come = sum(len(names) for names in planned.values()) - sum(len(names) for names in done.values())

    def interval(row: dict, low: str, high: str, single: bool, show=number) -> str:
        # a group of one run has no interval: every resample is that run (report/stats.py's markdown)
        return " (no interval: 1 run)" if single else f" [{show(float(row[low]))}, {show(float(row[high]))}]"

    try:
        counts = {row["group"]: int(row["runs"]) for row in summaries}
        sizes = set(counts.values())
        if not sizes:
            raise ValueError("no group")
        cells = [f"{KIND_NAMES.get(row['group'], row['group'])} IQM **{number(float(row['iqm']))}**"
                 f"{interval(row, 'iqm_low', 'iqm_high', counts[row['group']] == 1)}, mean "
                 f"**{number(float(row['mean']))}**{interval(row, 'mean_low', 'mean_high', counts[row['group']] == 1)}"
                 for row in summaries]
        pair = next(row for row in pairs if (row["x"], row["y"]) == ("hebbian", "static"))
        better = (f"P(Hebbian > static) **{float(pair['probability']):.2f}**"
                  f"{interval(pair, 'low', 'high', min(counts.values()) == 1, lambda value: f'{value:.2f}')}")
    except (KeyError, ValueError, StopIteration) as error:
        raise FigureError(f"{experiment}: {folder} is not a report of both kinds ({type(error).__name__}: {error})") \
            from None
    over = (f"{min(sizes)} run{'s' if min(sizes) > 1 else ''} of each kind" if len(sizes) == 1 else
            "runs of " + ", ".join(f"{group}: {count}" for group, count in counts.items()))
    over += " (95 % bootstrap intervals)" if max(sizes) > 1 else ""
    later = f"; {to_come} more run{'s' if to_come > 1 else ''} of the campaign to come" if to_come else ""
    return f"over {over}: {'; '.join(cells)}; {better} ([the report]" \
           f"({link(folder / 'summary.md', page)})){later}"


def remaining(page: Path, runs: Path = RUNS) -> str:
    """The campaign's remaining runs and what they will cost, projected from its completed runs in ``runs``
    (``experiments/cost.py``: on the workers those ran on, and on more where a benchmark's record projects it)."""
    try:
        plan = campaign_plan(runs)
    except (KeyError, TypeError, ValueError, OSError, *USER_ERRORS) as error:
        raise FigureError(f"the campaign's runs in {runs} cannot be read ({type(error).__name__}: {error})") from None
    return cost.summary(cost.project([planned for _, planned in plan]), page)
