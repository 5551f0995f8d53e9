"""The docs' campaign results read from a run's evaluation files (``results/paper/``; docs/generate.py).

A campaign run's evaluation (``result``, ``headline``), how its returns spread (``spread``), how long its episodes
lasted (``lengths``, ``lowest``, ``first``), how far an ant walked (``forward``) and its best centre's evaluation
(``best``), each from the run's own ``evaluation.json`` or ``evaluation_best.json``. Until a run is evaluated, the
marker holds ``PENDING``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from generate_records import FigureError, number

from cli.errors import USER_ERRORS
from es.files import read_json
from experiments import campaign
from experiments.paper_runs import HELD_OUT_SEED, latest_run
from experiments.progress import measure

ROOT = Path(__file__).resolve().parent.parent
RUNS = ROOT / "results" / "paper"  # the campaign's run folders

PENDING = "not yet: training in the campaign"


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
