"""``experiments/paper.py campaign --status``, and the progress page a chunk writes beside the runs.

For each run of ``experiments/paper/campaign.toml``, in its order: how far it got and what its generations cost,
from its own files (``progress.measure``), and for every run not yet complete, started or not, what the rest will
cost, projected from the completed runs of its kind (``cost.project``); then the campaign's remaining time in all.
``progress_page`` gives the same as a Markdown table, ``results/paper/progress.md``.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path

from cli.errors import USER_ERRORS, say
from experiments import campaign, cost, paper_runs
from experiments.paper_args import campaign_entries
from experiments.paper_runs import ROOT, latest_run, load_experiment, overrides, run_name, shown
from experiments.progress import PACE, Progress, measure


@dataclass(frozen=True)
class CampaignRun:
    """A run of the campaign: its name ("carracing hebbian seed 1"), its experiment's folder and what it asks for."""

    name: str
    folder: Path
    args: argparse.Namespace
    experiment: dict

    def planned(self, progress: Progress | None) -> cost.Planned:
        """The run as the projection of its cost sees it, ``progress`` its newest run's (None: not started)."""
        run = self.experiment["run"]
        return cost.Planned(
            name=self.name, experiment=self.args.experiment, kind=self.args.kind,
            group=shlex.join([self.args.experiment, self.args.kind,
                              *(["--variant", Path(self.args.variant).stem] if self.args.variant else []),
                              *overrides(self.args, "popsize", "generations")]),
            seed=self.args.seed if self.args.seed is not None else run["seed"],
            total=self.args.generations if self.args.generations is not None else run["generations"],
            progress=progress)


def campaign_runs(runs: Path) -> list[CampaignRun]:
    """The campaign's runs, in its order, each with its experiment's folder in ``runs``."""
    named = []
    for args in campaign_entries():
        experiment = load_experiment(args)[1]
        name = run_name(args, experiment)
        named.append(CampaignRun(name.replace("_seed", " seed ").replace("_", " "), runs / name, args, experiment))
    return named


def campaign_plan(runs: Path) -> list[tuple[CampaignRun, cost.Planned]]:
    """Each run of the campaign with its newest run's progress (``progress.measure``, whose errors it raises)."""
    return [(entry, entry.planned(None if (run_dir := latest_run(entry.folder)) is None else measure(run_dir)))
            for entry in campaign_runs(runs)]


def status() -> int:
    """Each campaign run: generations done of the total, the training time metrics.csv records, the mean time
    and environment steps of the last ten generations, the last population mean and centre, for a run not
    yet complete the time its remaining generations would take at the last ten's pace, and the machines it ran
    on (config.json's record); for every run not yet complete, started or not, its projection from the completed
    runs of its group (``cost.project``); then the campaign's remaining time in all (``cost.summary``)."""
    code, lines, plan = 0, {}, []
    for entry in campaign_runs(ROOT / paper_runs.RESULTS):
        run_dir = latest_run(entry.folder)
        if run_dir is None:
            lines[entry.name] = f"{entry.name}: not started"
            plan.append(entry.planned(None))
            continue
        try:
            progress = measure(run_dir)
        except (OSError, KeyError, TypeError, *USER_ERRORS, ValueError) as error:  # a hand-edited or damaged file
            print(f"paper.py: error: {entry.name}: {shown(run_dir)} cannot be read ({type(error).__name__}: {error})",
                  file=sys.stderr)
            code = 2
            continue
        plan.append(entry.planned(progress))
        line = (f"{entry.name}: {shown(run_dir)}: generation {progress.done} of {progress.total}"
                + (" (evaluated)" if progress.evaluated else ""))
        if progress.pace is not None:
            line += (f"; {progress.hours:.2f} h of training; the last {progress.paced} generations "
                     f"{progress.pace:.1f} s and {progress.steps:,.0f} env steps each; "
                     f"population mean {progress.mean:.1f}, centre {progress.centre:.1f}")
            if not progress.complete:
                line += f"; at that pace about {progress.hours_left:.1f} h more"
                if progress.hours_at_most is not None:
                    line += f", at most {progress.hours_at_most:.1f} h if every episode ran to its time limit"
        if progress.machines:
            line += f"; on {progress.machines}"
        lines[entry.name] = line
    projections = cost.project(plan)
    for projection in projections:
        lines[projection.planned.name] += f"; {projection.line()}"
    for line in lines.values():
        say(line)
    say(f"remaining: {cost.summary(projections)}")
    return code


def progress_page(runs: Path) -> str:
    """The campaign's runs in ``runs`` as a Markdown table (``runs/progress.md``, written at every chunk's end),
    and what its remaining runs will cost (``cost.summary``)."""
    lines = ["# The campaign's runs", "",
             "How far each run of `experiments/paper/campaign.toml` got, written by `experiments/paper.py` at the "
             "end of every chunk from the run's own files: the generation its `checkpoint.npz` holds, the "
             f"`seconds` and `env_steps` of its `metrics.csv` (the mean of the last {PACE} generations is "
             "the pace), the machines its `config.json` records. A run not yet complete is **partial**: its "
             "figures are those of the generations done so far, and its remaining time is the last generations' "
             "pace times the generations left. Generations grow longer as a run learns to stay in its episodes, so "
             "early in a run that says too little; the bound beside it is every remaining episode run to its "
             "environment's time limit at the last generations' cost per environment step. Every run not yet "
             "complete, started or not, is also projected from the completed runs of its experiment and kind (the "
             "seeds named): the mean of the time they took for the generations it has left, the fastest and the "
             "slowest of them in brackets.", "",
             "| run | generation | training so far | last generations, each | remaining, at that pace; at most "
             "| remaining, from the completed runs of its kind | population mean, centre | machines |",
             "|---|---|---|---|---|---|---|---|"]
    plan = campaign_plan(runs)
    projections = {projection.planned.name: projection for projection in cost.project([p for _, p in plan])}
    for entry, planned in plan:
        projection = projections.get(entry.name)
        projected = ("" if projection is None else "no completed run of its kind" if projection.estimate is None
                     else f"{projection.estimate.text()}, from {projection.sources_text()}")
        progress = planned.progress
        if progress is None:
            lines.append(f"| {entry.name} | not started | | | | {projected} | | |")
            continue
        state = ("complete, evaluated" if progress.evaluated else "complete, not yet evaluated" if progress.complete
                 else "**partial**")
        pace = (f"{progress.pace:.1f} s, {progress.steps:,.0f} env steps" if progress.pace is not None else "")
        left = ("" if progress.hours_left is None
                else f"about {progress.hours_left:.1f} h ({progress.hours + progress.hours_left:.1f} h in all)"
                + ("" if progress.hours_at_most is None else
                   f"; at most {progress.hours_at_most:.1f} h ({progress.hours + progress.hours_at_most:.1f} h)"))
        fitness = f"{progress.mean:.1f}, {progress.centre:.1f}" if progress.mean is not None else ""
        run_dir = latest_run(entry.folder)
        lines.append(f"| [{entry.name}]({run_dir.relative_to(runs).as_posix()}) | {progress.done} of {progress.total}, "
                     f"{state} | {progress.hours:.2f} h | {pace} | {left} | {projected} | {fitness} | "
                     f"{progress.machines} |")
    lines += ["", f"**Remaining.** {cost.summary(list(projections.values()), runs / campaign.PROGRESS)}"]
    return "\n".join(lines) + "\n"
