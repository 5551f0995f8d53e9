"""``experiments/paper.py EXPERIMENT report``: the two kinds compared over the seeds run so far.

Each seed's newest run of ``<experiment>_<kind>_seed<seed>`` (in results/paper, or under --runs) is scored by its
evaluation.json (``--centre best``: evaluation_best.json) with rliable's statistics (report/stats.py: IQM and
mean with 95 % bootstrap intervals, performance profiles, probability of improvement), one report per
evaluation environment, in ``<runs>/<experiment>_report/<environment>/``. A chunk of the campaign rewrites it
once both kinds have an evaluated run.
"""

from __future__ import annotations

import argparse
import sys
import tomllib
from pathlib import Path

import envs
from cli.hints import TRAIN_SCRIPTS
from experiments import campaign
from experiments.paper_runs import FILES, latest_run
from report.stats import DEFAULT_REPS


def report_folder(runs: Path, experiment: str, centre: str = "last") -> Path:
    """Where the report of ``experiment``'s runs in ``runs`` goes: one folder per evaluation environment in it."""
    return runs / (f"{experiment}_report" + ("" if centre == "last" else f"_{centre}"))


def evaluated_runs(runs: Path, experiment: str, kind: str, file: str = campaign.EVALUATION) -> list[Path]:
    """Each seed's newest run of ``kind`` in ``runs`` that has the evaluation ``file``."""
    return [run for folder in sorted(runs.glob(f"{experiment}_{kind}_seed*"))
            if (run := latest_run(folder)) is not None and (run / file).exists()]


def write_report(runs: Path, experiment: str, centre: str = "last", reps: int = DEFAULT_REPS) -> list[tuple]:
    """Static against Hebbian: each seed's newest run in ``runs``, scored by the evaluation of its ``centre``,
    one report per evaluation environment in ``report_folder``, its runs named relative to ``runs``. Returns
    (environment, folder, stats.Report) for each; stats.StatsError says what is missing."""
    from report import stats

    if not stats.available():
        raise stats.StatsError(f"the report needs rliable, which is not installed; install it with: "
                               f"{stats.INSTALL_HINT}")
    with open(FILES / f"{experiment}_static.toml", "rb") as handle:
        named = tomllib.load(handle)["evaluation"]["environment"].split(",")
    # as evaluation.json names them: the ids they resolve to (CarRacing-v0 -> CarRacing-v3)
    environments = [envs.resolve_env_id(env_id, notify=lambda *_: None) for env_id in named]
    score = "evaluation" if centre == "last" else "evaluation_best"  # report/stats.py's score of that centre's file
    file = stats.EVALUATIONS[score]
    groups = []
    for kind in TRAIN_SCRIPTS:
        found = evaluated_runs(runs, experiment, kind, file)
        if not found:
            raise stats.StatsError(f"no {kind} run in {runs}/{experiment}_{kind}_seed* has {file}; run python "
                                   f"experiments/paper.py {experiment} {kind} --seed N first")
        groups.append(f"{kind}={','.join(map(str, found))}")
    written = []
    for environment in environments:
        out = report_folder(runs, experiment, centre) / environment
        written.append((environment, out, stats.report(groups, out, score, environment, reps=reps, root=runs)))
    return written


def report(args: argparse.Namespace) -> int:
    """``EXPERIMENT report``: ``write_report`` of the runs in --runs, printed."""
    from report import stats

    try:
        written = write_report(args.runs, args.experiment, args.centre or "last", args.reps)
    except stats.StatsError as error:
        print(f"paper.py: error: {error}", file=sys.stderr)
        return 2
    for environment, out, result in written:
        print(f"## {environment} (written to {out})\n\n{result.markdown}", flush=True)
    return 0
