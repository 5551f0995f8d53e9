"""``experiments/paper.py EXPERIMENT KIND --reproduce N``: does this machine and code give a run's numbers?

The experiment's command is trained again for N generations in a temporary folder, with the run's seed and
settings, and its metrics.csv compared with the run's row by row, every column but the timings. A run made by
older code says, in its made_with.json, which commit and CPUs reproduce it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cli.errors import USER_ERRORS, say
from cli.hints import TRAIN_SCRIPTS
from experiments import campaign
from experiments.paper_runs import (
    ROOT,
    check_training,
    experiment_folder,
    generations_done,
    latest_run,
    load_experiment,
    overrides,
    run,
    shown,
    variant_flags,
)

TIMINGS = ("seconds", "total_seconds")  # the columns of metrics.csv that no two runs share


def reproduce(args: argparse.Namespace) -> int:
    """``--reproduce N``: the experiment's command trained again for N generations in a temporary folder, its
    metrics.csv compared with the run's, row by row, every column but the timings. Exit 0 when every row is
    the run's, 1 at the first that is not (named, with its columns), 2 when there is nothing to compare."""
    import tempfile

    from cli.config import TrainConfig, declared
    from es import files
    from settings import contradictions

    file, experiment = load_experiment(args)
    run_dir = latest_run(ROOT / experiment_folder(args, experiment))
    if run_dir is None:
        print(f"paper.py: error: no run in {shown(ROOT / experiment_folder(args, experiment))} to reproduce; train "
              "one first", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="reproduce-") as scratch:
        command = [sys.executable, TRAIN_SCRIPTS[args.kind], "--config", str(shown(file)), "--folder", scratch,
                   *variant_flags(args), *overrides(args, "seed", "popsize", "threads"),
                   "--generations", str(args.reproduce)]
        try:
            recorded = files.read_metrics(run_dir / "metrics.csv")[:generations_done(run_dir)]
            if len(recorded) < args.reproduce:
                raise ValueError(f"{shown(run_dir)} has " + (
                    f"{len(recorded)} generations saved; give --reproduce {len(recorded)} or less" if recorded
                    else "no generation saved yet"))
            # the fixed settings (not the workers nor the generations, which change no number of those run), but
            # the folder and the noise table's size, derived when the training starts
            asked = {name: value for name, value in check_training(args.kind, command).fixed().items()
                     if name not in ("folder", "noise_size")}
            differing = contradictions(TrainConfig.from_dict(files.read_json(run_dir / "config.json")).fixed(), asked,
                                       declared())
        except (*USER_ERRORS, OSError, ValueError, TypeError) as error:
            print(f"paper.py: error: {error}", file=sys.stderr)
            return 2
        if differing:
            print(f"paper.py: error: {shown(run_dir)} was made with other settings than "
                  f"{shown(file)} and the flags given: {', '.join(differing)}", file=sys.stderr)
            return 2
        code = run(command, dry_run=False)
        if code != 0:
            return code
        again = files.read_metrics(next(Path(scratch).glob("*/metrics.csv")))
    for row, theirs in zip(again, recorded[:args.reproduce]):
        columns = [f"{column} {row.get(column)} here, {value} in the run" for column, value in theirs.items()
                   if column not in TIMINGS and row.get(column) != value]
        if columns:
            say(f"generation {theirs['generation']} differs from {shown(run_dir)}: {'; '.join(columns)}"
                + made_with_note(run_dir))
            return 1
    say(f"generations 1-{args.reproduce}: every column but the timings is {shown(run_dir)}'s")
    return 0


def made_with_note(run_dir: Path) -> str:
    """For a run made by older code (its ``made_with.json``): where its generations come again."""
    from es import files

    try:
        label = files.read_json(run_dir / campaign.MADE_WITH)
        return (f" (the run was made by the code at commit {label['commit'][:12]}, and reproduces with it on "
                f"{label['reproduces_on']}: see its {campaign.MADE_WITH})")
    except (OSError, ValueError, TypeError, KeyError):
        return ""
