"""The docs' campaign results, from the campaign's run folders (``results/paper/``; docs/generate.py).

A campaign run's evaluation (``result``, ``headline``), how its returns spread (``spread``), its best centre's
evaluation (``best``), its frames (``frames``), an experiment's report over its seeds (``report``) and the
campaign's remaining runs with what they will cost (``remaining``), each read from the runs' own files. Until a
run is evaluated (or every run a report needs is in) the marker holds its pending text.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np
from generate_records import FigureError, listed, number

from cli.errors import USER_ERRORS
from es.files import read_json
from experiments import campaign, cost
from experiments.paper_args import campaign_entries
from experiments.paper_report import report_folder
from experiments.paper_runs import HELD_OUT_SEED, latest_run, load_experiment, run_name
from experiments.paper_status import campaign_plan
from experiments.progress import measure

ROOT = Path(__file__).resolve().parent.parent
RUNS = ROOT / "results" / "paper"  # the campaign's run folders

PENDING = "not yet: training in the campaign"

FRAMES_PENDING = "(the agent's frames, once its run is evaluated)"

REPORT_PENDING = "not yet: the campaign's seeds are still training"

KIND_NAMES = {"hebbian": "Hebbian", "static": "static"}


def evaluated(name: str, runs: Path, file: str = campaign.EVALUATION) -> Path | None:
    """The newest run folder of ``runs/name`` (the one experiments/paper.py continues), if it has been evaluated
    (its ``file``: the final centre's evaluation, or the best centre's)."""
    run = latest_run(runs / name)
    return run if run is not None and (run / file).is_file() else None


def link(path: Path, page: Path) -> str:
    return Path(os.path.relpath(path, page.parent)).as_posix()


def evaluation_of(name: str, environment: str | None, runs: Path,
                  file: str = campaign.EVALUATION) -> tuple[Path, dict, dict] | None:
    """The newest run of ``runs/name``, its evaluation ``file`` and the entry of ``environment`` there (the only
    one, where None); None until the run is evaluated."""
    run = evaluated(name, runs, file)
    if run is None:
        return None
    try:
        evaluation = read_json(run / file)
        entries = evaluation["environments"]
        found = ", ".join(entry["environment"] for entry in entries)
    except (KeyError, TypeError, ValueError, OSError, *USER_ERRORS) as error:
        raise FigureError(f"{name}: {run} is not a run this tool evaluated ({type(error).__name__}: {error})") from None
    chosen = [entry for entry in entries if environment in (None, entry["environment"])]
    if len(chosen) != 1:
        raise FigureError(f"{name}: {'no' if not chosen else 'several'} environment{'' if environment else 's'} "
                          f"{environment or ''} in {run / file} ({found}); name one in the marker")
    return run, evaluation, chosen[0]


def scored(run: Path, file: str, evaluation: dict, entry: dict, page: Path) -> str:
    """"**903 ± 45.1** ([100 episodes on held-out seeds](link)": one environment's returns in an evaluation
    ``file`` of ``run``, linked; a KeyError or TypeError where the file is not one."""
    seeds = "on held-out seeds" if evaluation["seed"] >= HELD_OUT_SEED else f"from seed {evaluation['seed']}"
    return (f"**{number(entry['mean'])} ± {number(entry['std'])}** ([{entry['episodes']} episodes {seeds}]"
            f"({link(run / file, page)})")


def result(name: str, environment: str | None, page: Path, runs: Path = RUNS) -> str:
    """One campaign run's evaluation: "**903 ± 45.1** (100 episodes on held-out seeds, generation 300 after 7.31 h
    of training on AMD EPYC 7B13, 2 workers, weights)"; the hours are the sum of metrics.csv's ``seconds``, the
    machines config.json's record."""
    found = evaluation_of(name, environment, runs)
    if found is None:
        return PENDING
    run, evaluation, entry = found
    try:
        headline = scored(run, campaign.EVALUATION, evaluation, entry, page)
        progress = measure(run)
    except (KeyError, TypeError, ValueError, OSError, *USER_ERRORS) as error:
        raise FigureError(f"{name}: {run} is not a run this tool evaluated ({type(error).__name__}: {error})") from None
    return (f"{headline}, generation {progress.done} after {number(progress.hours)} h of training"
            + (f" on {progress.machines}" if progress.machines else "") + f", [weights]({link(run, page)}))")


def best(name: str, environment: str | None, page: Path, runs: Path = RUNS) -> str:
    """One campaign run's best centre evaluated on the final centre's episodes: "**897 ± 61.2** (100 episodes on
    held-out seeds, the best centre: training return 921.5 at generation 248)"."""
    found = evaluation_of(name, environment, runs, campaign.BEST_EVALUATION)
    if found is None:
        return PENDING
    run, evaluation, entry = found
    try:
        headline = scored(run, campaign.BEST_EVALUATION, evaluation, entry, page)
        centre = evaluation["weights"]
        where = f" at generation {centre['generation']}" if centre.get("generation") is not None else ""
        return f"{headline}, the best centre: training return {number(centre['training_return'])}{where})"
    except (KeyError, TypeError, ValueError) as error:
        raise FigureError(f"{name}: {run / campaign.BEST_EVALUATION} is not a best centre's evaluation "
                          f"({type(error).__name__}: {error})") from None


def of_evaluation(holds: str, linked: bool = False):
    """A campaign run's marker rendered from its evaluation's entry for the environment: ``render(entry)`` (with
    ``linked``, as a link to the evaluation file), pending until the run is evaluated, and refused, naming the file
    and ``holds``, where the entry lacks what it reads."""
    def wrap(render):
        def marker(name: str, environment: str | None, page: Path, runs: Path = RUNS) -> str:
            found = evaluation_of(name, environment, runs)
            if found is None:
                return PENDING
            run, _, entry = found
            try:
                text = render(entry)
            except (KeyError, TypeError, ValueError, IndexError) as error:
                raise FigureError(f"{name}: {run / campaign.EVALUATION} holds no {holds} "
                                  f"({type(error).__name__}: {error})") from None
            return f"[{text}]({link(run / campaign.EVALUATION, page)})" if linked else text
        marker.__doc__ = render.__doc__
        return marker
    return wrap


@of_evaluation("mean and spread", linked=True)
def headline(entry: dict) -> str:
    """One campaign run's evaluation in a few characters, for a table of results: "[**867 ± 130**](evaluation.json)"."""
    return f"**{number(entry['mean'])} ± {number(entry['std'])}**"


@of_evaluation("returns")
def spread(entry: dict) -> str:
    """How one campaign run's evaluation returns spread: "median 905, quartiles 888–915, lowest 106, highest 936;
    4 of 100 episodes below three quarters of the mean (650)" (numpy's percentiles, linear)."""
    returns = np.asarray(entry["returns"], dtype=np.float64)
    low, median, high = np.percentile(returns, [25, 50, 75])
    floor = 0.75 * returns.mean()
    return (f"median {number(median)}, quartiles {number(low)}–{number(high)}, lowest {number(returns.min())}, "
            f"highest {number(returns.max())}; {int((returns < floor).sum())} of {returns.size} episodes below three "
            f"quarters of the mean ({number(floor)})")


@of_evaluation("episode lengths with their returns")
def lengths(entry: dict) -> str:
    """How long one campaign run's evaluation episodes lasted, in steps as ``evaluation.json`` counts them (a
    burn-in included): "every one of its 100 episodes ends at step 1000"; "54 of its 100 episodes last 1000 steps,
    the longest, and score 651 to 889; the other 46 end at steps 150–997 (median 734), with a median return of 514";
    or, where no two episodes share the longest length, "its 100 episodes end at steps 242–251 (median 243)"."""
    steps = np.asarray(entry["steps"], dtype=np.int64)
    returns = np.asarray(entry["returns"], dtype=np.float64)
    if steps.size == 0 or steps.shape != returns.shape:
        raise ValueError(f"{steps.size} episode lengths for {returns.size} returns")
    longest = int(steps.max())
    full, short = steps == longest, steps < longest
    if not short.any():
        return f"every one of its {steps.size} episodes ends at step {longest}"
    if full.sum() < 2:  # no common longest length: the range
        return (f"its {steps.size} episodes end at steps {int(steps.min())}–{longest} "
                f"(median {number(float(np.median(steps)))})")
    kept, cut = returns[full], steps[short]
    return (f"{int(full.sum())} of its {steps.size} episodes last {longest} steps, the longest, and score "
            f"{number(kept.min())} to {number(kept.max())}; the other {int(short.sum())} end at steps "
            f"{int(cut.min())}–{int(cut.max())} (median {number(float(np.median(cut)))}), with a median return of "
            f"{number(float(np.median(returns[short])))}")


@of_evaluation("returns with their seeds and lengths")
def lowest(entry: dict) -> str:
    """A campaign run's lowest evaluation episode: "the lowest, on seed 2³¹ + 97, scores 79.3 and ends at step 150"
    (its seed as an offset from the held-out seeds' start, where it is one of them)."""
    returns = entry["returns"]
    worst = min(range(len(returns)), key=returns.__getitem__)
    seed, score, length = int(entry["seeds"][worst]), float(returns[worst]), int(entry["steps"][worst])
    shown = f"2³¹ + {seed - HELD_OUT_SEED}" if seed >= HELD_OUT_SEED else str(seed)
    return f"the lowest, on seed {shown}, scores {number(score)} and ends at step {length}"


@of_evaluation("returns with their lengths")
def first(entry: dict) -> str:
    """A campaign run's first evaluation episode, the one its frames.png shows: "734 steps, return 912"."""
    return f"{int(entry['steps'][0])} steps, return {number(float(entry['returns'][0]))}"


@of_evaluation("forward distance, which an ant's evaluation records")
def forward(entry: dict) -> str:
    """How far a campaign run's ant walked toward +x in its evaluation, mean ± std over the episodes: "17.0 ± 0.4 m
    forward" (``forward`` in ``evaluation.json``)."""
    return f"{number(entry['forward_mean'])} ± {number(entry['forward_std'])} m forward"


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
