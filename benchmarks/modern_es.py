#!/usr/bin/env python
"""The original's ES settings against the modern options, one seed, the same budget: the tables of
docs/modern-es.md.

    python benchmarks/modern_es.py --environment HalfCheetah-v5 --popsize 48 --generations 100

Each setting is one ``train_static.py`` run (``--threads 1``, ``--seed``, the budget given here), in
``<--folder>/<environment>/<setting>``:

- ``faithful``: the original's defaults (SGD, lr 0.2, σ 0.1, decay 0.995, rank_std, no normalisation);
- ``modern``: ``MODERN``, the common choices of modern ES code (Adam, lr 0.01, σ 0.02, observation
  normalisation, L2 0.005), untuned.

Both evaluate their centre every 5 generations on 10 episodes (``--eval_every 5 --eval_episodes 10``), a log
that no update reads. A run already complete is not trained again; one cut short resumes. The final centre is
then evaluated by ``evaluate_static.py`` on ``--episodes`` episodes per body from seed 2**31, seeds no training
episode uses. The record (``modern_es-<environment>``, not timed: a seeded run's returns are the same at any
load) holds, per setting and body, the return and, for ants, the distance walked forward, each as mean ± std
over the episodes, and the run's own last centre evaluation; and, per setting, how its centre evaluations went
(how many, how many below zero and below the one before; the first, highest and last).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import sys
from pathlib import Path

from record import ROOT, Record, add_results_flag, documented_parser

from cli.flags import positive_int, seed_value
from es import files
from es.loop import EVAL_SEEDS
from es.runfolder import RunFolderError, generations_done, latest_run

CENTRE_EVALUATION = ["--eval_every", "5", "--eval_episodes", "10"]
MODERN = ["--optimizer", "adam", "--lr", "0.01", "--sigma", "0.02", "--obs_norm", "--l2coeff", "0.005"]
SETTINGS = {"faithful": [], "modern": MODERN}
HELD_OUT = EVAL_SEEDS[0]  # 2**31: seeds from here on are the centre evaluation's, never a training's


def run_folder(args: argparse.Namespace, setting: str) -> Path:
    return args.folder / args.environment.replace(",", "+") / setting


def train(args: argparse.Namespace, setting: str) -> Path:
    """The setting's run, trained (or resumed) to ``--generations``; SystemExit with the script's code if it
    fails."""
    folder = run_folder(args, setting)
    run = latest_run(folder)
    if generations_done(run) >= args.generations:
        print(f"{setting}: {run} is complete", flush=True)
        return run
    start = ["--resume", str(run)] if run is not None else [
        "--environment", args.environment, "--popsize", str(args.popsize), "--seed", str(args.seed),
        "--folder", str(folder), *CENTRE_EVALUATION, *SETTINGS[setting]]
    command = [sys.executable, str(ROOT / "train_static.py"), *start, "--generations", str(args.generations),
               "--threads", "1", "--print_every", "10"]
    print(f"$ python train_static.py {' '.join(command[2:])}", flush=True)
    code = subprocess.run(command).returncode
    run = latest_run(folder)
    if code != 0 or run is None or generations_done(run) < args.generations:
        print(f"modern_es.py: error: the {setting} run stopped (exit code {code}); the same command resumes it",
              file=sys.stderr)
        raise SystemExit(2 if code == 2 else 1)
    return run


def evaluate(args: argparse.Namespace, run: Path) -> dict:
    """``evaluate_static.py``'s statistics of the run's final centre (its JSON), written beside the run."""
    out = run.parent / f"evaluation-{run.name}.json"
    command = [sys.executable, str(ROOT / "evaluate_static.py"), "--path_weights", str(run), "--episodes",
               str(args.episodes), "--seed", str(HELD_OUT), "--json", str(out)]
    print(f"$ python evaluate_static.py {' '.join(command[2:])}", flush=True)
    if subprocess.run(command).returncode != 0:
        print("modern_es.py: error: the evaluation failed", file=sys.stderr)
        raise SystemExit(1)
    return json.loads(out.read_text())


def plus_minus(mean: float, std: float, unit: str = "") -> str:
    return f"{mean:,.1f} ± {std:,.1f}{unit}"


def centre_evaluations(run: Path) -> list[tuple[int, float, float]]:
    """The run's centre evaluations, in order: (generation, mean, std over its episodes), from metrics.csv."""
    rows = files.read_metrics(run / "metrics.csv")
    found = [(int(row["generation"]), float(row["center_eval_mean"]), float(row["center_eval_std"])) for row in rows]
    return [(generation, mean, std) for generation, mean, std in found if not math.isnan(mean)]


def centre_log(run: Path) -> str:
    """The run's last centre evaluation, mean ± std over its episodes."""
    evaluations = centre_evaluations(run)
    if not evaluations:
        return "–"
    generation, mean, std = evaluations[-1]
    return f"{plus_minus(mean, std)} (generation {generation})"


CENTRE_COLUMNS = ["settings", "evaluations", "below zero", "lower than the one before", "first", "highest", "last"]


def centre_row(setting: str, run: Path) -> list:
    """How the run's centre evaluations went: how many, how many below zero and below the one before, and its
    first, highest and last mean return, each with its generation."""
    evaluations = centre_evaluations(run)
    means = [mean for _, mean, _ in evaluations]

    def at(generation: int, mean: float) -> str:
        return f"{mean:,.1f} (generation {generation})"

    if not evaluations:
        return [setting, 0, 0, 0, "–", "–", "–"]
    highest = max(evaluations, key=lambda evaluation: evaluation[1])  # the first of equal highs
    return [setting, len(means), sum(mean < 0 for mean in means),
            sum(later < earlier for earlier, later in zip(means, means[1:])), at(*evaluations[0][:2]),
            at(*highest[:2]), at(*evaluations[-1][:2])]


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    record = Record(f"modern_es-{args.environment.replace(',', '+')}", timed=False)
    rows, columns, centres = [], None, []
    for setting in SETTINGS:
        try:
            run = train(args, setting)
        except RunFolderError as error:  # a run folder there whose checkpoint cannot be read
            print(f"modern_es.py: error: {error}", file=sys.stderr)
            return 2
        evaluation = evaluate(args, run)
        cells, heads = [], []
        for body in evaluation["environments"]:
            name = body["environment"]
            heads.append(f"{name}: return")
            cells.append(plus_minus(body["mean"], body["std"]))
            record.add(f"{setting}_{name}_return", f"{setting} settings, after {args.generations} generations: "
                       f"{name}'s return, one value per evaluation episode", "", body["returns"])
            if "forward" in body:
                heads.append(f"{name}: forward x")
                cells.append(plus_minus(body["forward_mean"], body["forward_std"], " m"))
        columns = columns or ["settings", *heads, "the run's own last centre evaluation (10 episodes)"]
        rows.append([setting, *cells, centre_log(run)])
        centres.append(centre_row(setting, run))
        record.note(f"{setting}_run", {"folder": str(run), "command": files.read_json(run / "config.json").get(
            "command"), "mean_return": statistics.fmean(b["mean"] for b in evaluation["environments"])})
    record.table("results", columns, rows)
    record.table("centre", CENTRE_COLUMNS, centres)
    record.note("protocol", {"environment": args.environment, "popsize": args.popsize,
                             "generations": args.generations, "seed": args.seed, "episodes": args.episodes,
                             "first_evaluation_seed": HELD_OUT, "settings": SETTINGS,
                             "centre_evaluation": CENTRE_EVALUATION})
    record.write(args.results)
    return 0


def parse(argv: list[str] | None) -> argparse.Namespace:
    parser = documented_parser(__doc__)
    parser.add_argument("--environment", default="HalfCheetah-v5",
                        help="a Gymnasium id, or several separated by commas, as train_static.py takes them")
    parser.add_argument("--popsize", type=positive_int, default=48)
    parser.add_argument("--generations", type=positive_int, default=100)
    parser.add_argument("--seed", type=seed_value, default=1)
    parser.add_argument("--episodes", type=positive_int, default=10, help="evaluation episodes per body")
    parser.add_argument("--folder", type=Path, default=Path("runs/modern_es"),
                        help="where the runs go: <FOLDER>/<environment>/<setting> (default: runs/modern_es)")
    add_results_flag(parser)
    return parser.parse_args(argv)


if __name__ == "__main__":
    sys.exit(main())
