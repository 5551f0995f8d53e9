#!/usr/bin/env python
"""What makes a static ant stand: one page, ``results/paper/STATIC_ANT.md``, and its figure, generated.

    python experiments/stand.py            # writes the page and static_ant.png from the runs' files
    python experiments/stand.py --check    # writes nothing; exit 1 if the page differs from what they give

The paper's static ant falls: in every episode of its seed-1 run its torso rests below the 0.26 m at which pyBullet
ends an episode, and the original's rule that ignores the end for the first 201 policy steps stops it at step 202.
The study changes one setting at a time (``experiments/static_ant/*.toml``, variant files of the paper's experiment:
``paper.py ant static --variant FILE``), trains each change for ``GENERATIONS`` generations on three seeds (campaign
entries), and compares it with the paper's own runs over the same generations, which are the first rows of the
campaign's ``ant_static_seed*`` runs: the same command gives the same generations whatever the total.

What is measured, from each run's metrics.csv: the population's mean episode length in policy steps, each generation
(its environment steps over its episodes, less the burn-in). An episode that falls ends at step 202; one that stands
goes on, to at most the 1,000 steps of the time limit (less the burn-in). A run **stands** where that mean exceeds
``STANDS`` steps over its generations ``GENERATIONS - 4`` to ``GENERATIONS``: a population that falls stays within a
few steps of 202 (the paper's seed 1 did, for 300 generations). A change's runs that are evaluated add their final
centre's episodes (evaluation.json): how many of them last past step 202 on each body.

A run trained or evaluated since the page was written makes ``--check`` say the page is behind (exit 0): the campaign
rewrites it at the end of each of its chunks.
"""

from __future__ import annotations

import argparse
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # run as a script
    sys.path.insert(0, str(ROOT))
from experiments.pages import covered, runs_line, settle  # noqa: E402  (after the repository's root is on the path)

RUNS = ROOT / "results" / "paper"
VARIANTS = ROOT / "experiments" / "static_ant"
PAGE_NAME, FIGURE_NAME = "STATIC_ANT.md", "static_ant.png"
SEEDS = (1, 2, 3)
GENERATIONS = 20  # each change's run; the paper's runs are read over as many
LAST = 5  # the generations whose mean episode decides whether a run stands
FALLS_AT = 202  # policy steps: the original ignores the end of an episode before this step
STANDS = 250  # mean policy steps per episode above which a population stands
BUDGET = 12  # core-hours, at most, for the changes' runs (the paper's are the campaign's own)


class StudyError(Exception):
    """A run's files cannot be read, or the page cannot be written; the message names it."""


@dataclass(frozen=True)
class Arm:
    name: str  # "paper", or a variant file's name
    change: str  # in words
    folder_name: str  # the runs' folders in results/paper, before the seed: ant_static_sigma

    def folder(self, runs: Path, seed: int) -> Path:
        return runs / f"{self.folder_name}_seed{seed}"


def change_of(path: Path) -> str:
    """A variant file's change in words: its leading comment from "one change: " to the end of that sentence."""
    comment = " ".join(line.lstrip("# ").strip() for line in path.read_text().splitlines() if line.startswith("#"))
    match = re.search(r"one change: (.*?\.)(\s|$)", comment)
    return match[1] if match else path.stem


def arms() -> list[Arm]:
    paper = Arm("paper", "none: the paper's settings (the campaign's runs, their first "
                f"{GENERATIONS} generations)", "ant_static")
    return [paper, *(Arm(path.stem, change_of(path), f"ant_static_{path.stem}")
                     for path in sorted(VARIANTS.glob("*.toml")))]


@dataclass(frozen=True)
class Run:
    arm: Arm
    seed: int
    folder: Path  # the run folder (the newest in the experiment's folder)
    lengths: np.ndarray  # mean policy steps per episode, generations 1.. (at most GENERATIONS)
    burn_in: int
    evaluation: dict | None  # evaluation.json, once evaluated
    core_hours: float  # its first GENERATIONS generations' wall-clock time times its workers

    @property
    def stands(self) -> bool:
        return len(self.lengths) >= GENERATIONS and float(self.lengths[GENERATIONS - LAST:GENERATIONS].mean()) > STANDS

    @property
    def state(self) -> str:
        return "evaluated" if self.evaluation is not None else "trained"


def burn_in_of(config: dict) -> int:
    """The burn-in steps of a run's episodes: the pyBullet ant's, where its config.json's wrapper stack has the
    burn-in (read from the record, not from the recipes this process has imported: a custom one wins over the
    built-in for every ant once imported)."""
    from envs.recipes import PYBULLET_ANT

    first = config["env"]["env_ids"][0]
    return PYBULLET_ANT.burn_in if "BurnIn" in config["wrappers"][first] else 0


def read_run(arm: Arm, seed: int, runs: Path) -> Run | None:
    """A run of ``arm`` with ``seed`` once it has ``GENERATIONS`` generations saved (None before)."""
    from es import files
    from experiments.paper_runs import generations_done, latest_run

    run_dir = latest_run(arm.folder(runs, seed))
    try:
        if run_dir is None or generations_done(run_dir) < GENERATIONS:
            return None
        config = files.read_json(run_dir / "config.json")
        rows = files.read_metrics(run_dir / "metrics.csv")[:GENERATIONS]
        environment, popsize = config["env"]["environment"], config["es"]["popsize"]
        episodes = (popsize + 1) * len(environment.split(",")) * config["es"].get("episodes", 1)  # and the centre
        burn_in = burn_in_of(config)
        lengths = np.array([float(row["env_steps"]) / episodes - burn_in for row in rows])
        core_hours = float(rows[-1]["total_seconds"]) * int(config.get("workers", 1)) / 3600
        evaluation = None
        if arm.name != "paper" and (run_dir / "evaluation.json").exists():
            evaluation = files.read_json(run_dir / "evaluation.json")
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise StudyError(f"{run_dir}: {type(error).__name__}: {error}") from None
    return Run(arm, seed, run_dir, lengths, burn_in, evaluation, core_hours)


def stood(run: Run) -> str:
    """The final centre's evaluation, in the paper's episodes (its burn-in included in ``steps``): on each body, how
    many episodes lasted past step 202."""
    from envs.recipes import PYBULLET_ANT

    parts = []
    for body in run.evaluation["environments"]:
        if ":" in body["environment"]:
            raise StudyError(f"{run.folder}: evaluated on {body['environment']}, not in the paper's episodes; the "
                             "study evaluates every change in them ([evaluation] environment left as the paper's)")
        steps = np.asarray(body["steps"]) - PYBULLET_ANT.burn_in
        name = body["environment"].removesuffix("BulletEnv-v0")
        parts.append(f"{name} {int((steps > FALLS_AT).sum())}/{len(steps)} ({body['mean']:.1f})")
    return ", ".join(parts)


def figure(runs: list[Run], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [arm.name for arm in arms()]
    colours = plt.get_cmap("tab10")
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for run in runs:
        index = names.index(run.arm.name)
        ax.plot(np.arange(1, len(run.lengths) + 1), run.lengths, color=colours(index), lw=1.4,
                label=run.arm.name if run is next(r for r in runs if r.arm == run.arm) else None)
    ax.axhline(FALLS_AT, color="grey", lw=0.8, ls="--")
    ax.axhline(STANDS, color="grey", lw=0.8, ls=":")
    ax.set(xlabel="generation", ylabel="mean episode, policy steps", xlim=(1, GENERATIONS),
           title="The static ant: does the population stand past step 202?")
    if runs:
        ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100, metadata={"Software": None})
    plt.close(fig)


def runs_in(runs_root: Path) -> list[Run]:
    """The study's runs found in ``runs_root``, the paper's own among them."""
    return [run for arm in arms() for seed in SEEDS if (run := read_run(arm, seed, runs_root))]


def pending(found: list[Run]) -> list[str]:
    """The study's runs not yet in ``found``: "no_burn_in seed 3"."""
    return [f"{arm.name} seed {seed}" for arm in arms() for seed in SEEDS
            if not any(run.arm == arm and run.seed == seed for run in found)]


def answer(found: list[Run]) -> str:
    """The study's result in one sentence: its runs to come, or the changes that let more seeds stand."""
    standing = {arm.name: sum(run.stands for run in found if run.arm == arm) for arm in arms()}
    return result(standing, len(pending(found)))


def render(runs_root: Path) -> tuple[str, list[Run]]:
    found = runs_in(runs_root)
    rows = []
    for arm in arms():
        mine = [run for run in found if run.arm == arm]
        seeds = ", ".join(f"{run.seed}: {run.lengths[GENERATIONS - LAST:GENERATIONS].mean():.0f}" for run in mine)
        count = f"{sum(run.stands for run in mine)} of {len(mine)}" if mine else "not yet run"
        evaluated = "; ".join(f"seed {run.seed}: {stood(run)}" for run in mine if run.evaluation is not None)
        rows.append(f"| {arm.name} | {arm.change} | {seeds or '—'} | {count} | {evaluated or '—'} |")
    spent = sum(run.core_hours for run in found if run.arm.name != "paper")
    to_come = pending(found)
    lines = [
        "# What makes a static ant stand", "",
        "[← the replication report](REPLICATION.md) · generated by `python experiments/stand.py` from the "
        "runs' files (do not edit: `python experiments/stand.py --check` compares)", "",
        "The paper's static ant, trained with the paper's settings, fell in every episode of its seed-1 run: its "
        "torso rests below the 0.26 m at which pyBullet ends an episode, and the original ignores that end for the "
        f"first 201 policy steps, so every episode stops at step {FALLS_AT}. Each change below is one setting of "
        "the paper's experiment changed ([experiments/static_ant/](../../experiments/static_ant/), `python "
        "experiments/paper.py ant static --variant FILE`), trained for "
        f"{GENERATIONS} generations on seeds {', '.join(map(str, SEEDS))} by the campaign.", "",
        f"A run **stands** where its population's mean episode exceeds {STANDS} policy steps over generations "
        f"{GENERATIONS - LAST + 1}–{GENERATIONS}; a population that falls stays within a few steps of {FALLS_AT}. "
        "The mean episode is each generation's environment steps over its episodes (the population and the centre "
        "on every training body), less the burn-in. An evaluated change adds its final centre's episodes in the "
        f"paper's own (the burn-in and the grace included) on its three bodies: how many lasted past step {FALLS_AT}, "
        "and their mean score.", "",
        "**The result**: " + answer(found), "",
        "| change | in words | mean episode, generations "
        f"{GENERATIONS - LAST + 1}–{GENERATIONS}, by seed | runs that stand | final centre: episodes past step "
        f"{FALLS_AT} (mean score), by body |",
        "|---|---|---|---|---|", *rows, "",
        f"![the mean episode of each run, generation by generation]({FIGURE_NAME})", "",
        f"The changes' runs took {spent:.1f} core-hours (their training's wall-clock time times its workers, from "
        f"metrics.csv and config.json), of the study's {BUDGET} at most; the paper's runs are the campaign's own.", "",
        "Not yet run: " + (", ".join(to_come) if to_come else "none") + ". Not in this study: a larger population "
        "(twice the paper's 200 doubles a run's cost, beyond the budget) and another scale of the initial weights "
        "(no setting changes a static network's initial weights). More generations are the campaign's own "
        "300-generation runs ([progress.md](progress.md)).", "",
        runs_line(f"{run.arm.name}:{run.seed}:{run.state}" for run in found), "",
    ]
    return "\n".join(lines), found


def result(standing: dict[str, int], to_come: int) -> str:
    """The study's answer in one sentence, once every run is in: the changes that let more seeds stand than
    the paper's settings do."""
    if to_come:
        return f"not yet decided, {to_come} of its {len(standing) * len(SEEDS)} runs to come."
    paper = standing["paper"]
    better = [name for name, count in standing.items() if name != "paper" and count > paper]
    if not better:
        return (f"none of the changes lets more of its seeds stand than the paper's settings do ({paper} of "
                f"{len(SEEDS)}).")
    return (", ".join(f"{name} ({standing[name]} of {len(SEEDS)})" for name in better) + " let more seeds stand "
            f"than the paper's settings ({paper} of {len(SEEDS)}).")


def behind(current: str, generated: str) -> bool:
    """Whether ``current`` lacks only runs trained or evaluated since (each of its runs is in ``generated``,
    or is there evaluated now)."""
    now, then = covered(generated), covered(current)
    return then != now and all(entry in now or entry.replace(":trained", ":evaluated") in now for entry in then)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="experiments/stand.py", description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 if the page differs from what the files give")
    parser.add_argument("--runs", type=Path, default=RUNS, metavar="DIR",
                        help=f"the campaign's folder; the page is DIR/{PAGE_NAME} (default: results/paper)")
    args = parser.parse_args(argv)
    page, picture = args.runs / PAGE_NAME, args.runs / FIGURE_NAME
    try:
        if not args.runs.is_dir():
            raise StudyError(f"--runs {args.runs}: not a folder")
        generated, found = render(args.runs)

        def write() -> None:
            figure(found, picture)
            page.write_text(generated)
            print(f"wrote {page} and {picture}")

        return settle(page, generated, args.check, "python experiments/stand.py", write,
                      lambda current: "the runs trained or evaluated since it was written"
                      if behind(current, generated) else None, outputs=(picture,))
    except (StudyError, OSError) as error:
        print(f"{parser.prog}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
