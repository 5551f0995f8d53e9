#!/usr/bin/env python
"""Every strategy on one task, several seeds each, on the static network and on the Hebbian one: the tables of
docs/strategies.md.

    python benchmarks/strategies.py --environment CartPole-v1 --popsize 16 --generations 30 --seeds 5 --jobs 2

Each (kind, strategy) pair is one launch of ``experiments/seeds.py`` (seeds 1 .. ``--seeds``), the command a user
would type: ``train_static.py`` or ``train_hebb.py`` with ``--environment``, ``--popsize``, ``--generations`` and
``--strategy`` (``openai``, the original's, with its defaults: the command without ``--strategy``), in
``<--folder>/<environment>/<kind>_<strategy>``. Running the same command again resumes what a stop left
unfinished, and refuses a folder trained with other settings. A run's score is ``report_runs.py``'s ``final``
(its last centre's return). The record (``strategies-<environment>``, not timed: a seeded run's scores are the
same at any load) holds, for each kind, the strategies' IQM and mean with their stratified bootstrap 95 %
intervals (``report.stats``), the median, P(X > openai) and every seed's score; with both kinds, each
strategy's static runs against its Hebbian ones.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from record import ROOT, Record, add_results_flag, documented_parser

from cli.flags import positive_int
from es.strategies import STRATEGIES
from es.strategies.cma import library_class
from report import stats

KINDS = {"static": "train_static.py", "hebbian": "train_hebb.py"}
DEFAULT_STRATEGIES = ("openai", "pgpe", "snes", "ars", "sep_cma_es")  # cma_es: a d x d matrix, for small d only
BASELINE = "openai"


def launch_folder(args: argparse.Namespace, kind: str, strategy: str) -> Path:
    return args.folder / args.environment / f"{kind}_{strategy}"


def launch(args: argparse.Namespace, kind: str, strategy: str) -> int:
    """Train the seeds of one (kind, strategy) pair, or resume them: ``experiments/seeds.py``'s exit code."""
    training = [KINDS[kind], "--environment", args.environment, "--popsize", str(args.popsize),
                "--generations", str(args.generations), "--folder", str(launch_folder(args, kind, strategy))]
    training += [] if strategy == BASELINE else ["--strategy", strategy]
    command = [sys.executable, str(ROOT / "experiments" / "seeds.py"), "--seeds", str(args.seeds),
               *(["--jobs", str(args.jobs)] if args.jobs else []), "--", *training]
    print(f"$ {' '.join(['python', 'experiments/seeds.py', *command[2:]])}", flush=True)
    return subprocess.run(command, cwd=Path.cwd()).returncode


def seed_of(run: Path) -> int:
    """The seed of a run of a launch (``<launch>/seed<k>/<run folder>``)."""
    return int(run.parent.name.removeprefix("seed"))


def estimate(value: float, low: float, high: float, runs: int, digits: int = 1) -> dict | str:
    """A table cell with its interval; a single run has none (``report.stats.NO_INTERVAL``)."""
    if runs < 2:
        return f"{value:.{digits}f} {stats.NO_INTERVAL}"
    return {"value": value, "low": low, "high": high, "digits": digits}


def kind_table(scores: dict[str, list[float]], summaries: dict[str, stats.Summary], reps: int) -> list[list]:
    """One row per strategy: runs, IQM, mean, median, P(X > openai), each seed's score."""
    against = {pair.x: pair for pair in stats.improvements(scores, reps) if pair.y == BASELINE}
    rows = []
    for name, summary in summaries.items():
        pair = against.get(name)
        rows.append([name, summary.runs, estimate(summary.iqm, summary.iqm_low, summary.iqm_high, summary.runs),
                     estimate(summary.mean, summary.mean_low, summary.mean_high, summary.runs),
                     round(summary.median, 1),
                     "—" if pair is None else estimate(pair.probability, pair.low, pair.high, summary.runs, 2),
                     ", ".join(f"{value:.1f}" for value in scores[name])])
    return rows


def kinds_table(scores: dict[str, dict[str, list[float]]], summaries: dict[str, dict[str, stats.Summary]],
                reps: int) -> list[list]:
    """One row per strategy run on both kinds: each kind's IQM (``summaries``, each group's bootstrap seeded on
    its own) and P(static > Hebbian)."""
    rows = []
    for strategy in [name for name in scores["static"] if name in scores["hebbian"]]:
        pair = {kind: scores[kind][strategy] for kind in ("static", "hebbian")}
        [better] = [p for p in stats.improvements(pair, reps) if p.x == "static"]
        shown = [summaries[kind][strategy] for kind in ("static", "hebbian")]
        rows.append([strategy, *(estimate(s.iqm, s.iqm_low, s.iqm_high, s.runs) for s in shown),
                     estimate(better.probability, better.low, better.high, min(s.runs for s in shown), 2)])
    return rows


def train_and_score(args: argparse.Namespace, record: Record) -> tuple[dict, dict]:
    """Each (kind, strategy) launch trained or resumed, and its runs' final scores (seed by seed, measures of
    ``record``) with each group's summary; SystemExit with the launch's code where one stops."""
    scores: dict[str, dict[str, list[float]]] = {kind: {} for kind in args.kinds}
    for kind in args.kinds:
        for strategy in args.strategies:
            code = launch(args, kind, strategy)
            if code != 0:
                print(f"strategies.py: error: the {kind} {strategy} runs stopped (exit code {code}); the same command "
                      "resumes them", file=sys.stderr)
                raise SystemExit(2 if code == 2 else 1)
            found = stats.collect([f"{strategy}={launch_folder(args, kind, strategy)}"], "final")[strategy]
            scores[kind][strategy] = [found[run] for run in sorted(found, key=seed_of)]
            record.add(f"{kind}_{strategy}", f"{kind} network, {strategy}: each seed's final score on "
                       f"{args.environment}", "", scores[kind][strategy])
    summaries = {kind: {s.group: s for s in stats.summarise(scores[kind], args.reps)} for kind in scores}
    return scores, summaries


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    if not stats.available():
        print(f"strategies.py: error: needs rliable, which is not installed; {stats.INSTALL_HINT}", file=sys.stderr)
        return 2
    try:
        for name in {"cma_es", "sep_cma_es"} & set(args.strategies):
            library_class(name, separable=True)  # the cmaes library, before any run
        record = Record(f"strategies-{args.environment}", ("rliable",), timed=False)
        scores, summaries = train_and_score(args, record)
    except ValueError as error:  # the cmaes library missing; a launch folder without its runs (stats.StatsError)
        print(f"strategies.py: error: {error}", file=sys.stderr)
        return 2
    for kind in scores:
        record.table(kind, ["strategy", "runs", "IQM [95 % CI]", "mean [95 % CI]", "median",
                            f"P(X > {BASELINE}) [95 % CI]", "final score, seeds 1 .."],
                     kind_table(scores[kind], summaries[kind], args.reps))
    if set(KINDS) <= set(scores):
        record.table("kinds", ["strategy", "static: IQM [95 % CI]", "Hebbian: IQM [95 % CI]",
                               "P(static > Hebbian) [95 % CI]"], kinds_table(scores, summaries, args.reps))
    record.note("protocol", {"environment": args.environment, "popsize": args.popsize,
                             "generations": args.generations, "seeds": args.seeds, "score": "final",
                             "reps": args.reps, "folder": str(args.folder)})
    record.write(args.results)
    return 0


def names(text: str, valid, flag: str, parser: argparse.ArgumentParser) -> list[str]:
    chosen = [name for name in text.split(",") if name]
    unknown = [name for name in chosen if name not in valid]
    if unknown or not chosen or len(set(chosen)) != len(chosen):
        parser.error(f"{flag} {text}: give distinct names, comma-separated, from {', '.join(valid)}")
    return chosen


def parse(argv: list[str] | None) -> argparse.Namespace:
    parser = documented_parser(__doc__)
    parser.add_argument("--environment", default="CartPole-v1", help="a Gymnasium id, as train_static.py takes it")
    parser.add_argument("--kinds", default=",".join(KINDS), help="comma-separated, of " + ", ".join(KINDS))
    parser.add_argument("--strategies", default=",".join(DEFAULT_STRATEGIES),
                        help="comma-separated, of " + ", ".join(list(STRATEGIES)))
    parser.add_argument("--popsize", type=positive_int, default=16)
    parser.add_argument("--generations", type=positive_int, default=30)
    parser.add_argument("--seeds", type=positive_int, default=5, help="runs per strategy and kind: seeds 1 .. N")
    parser.add_argument("--jobs", type=positive_int, default=None,
                        help="runs at a time (experiments/seeds.py's --jobs)")
    parser.add_argument("--folder", type=Path, default=Path("runs/strategies"),
                        help="where the runs go: <FOLDER>/<environment>/<kind>_<strategy> (default: runs/strategies)")
    parser.add_argument("--reps", type=positive_int, default=stats.DEFAULT_REPS, help="bootstrap replications")
    add_results_flag(parser)
    args = parser.parse_args(argv)
    args.kinds = names(args.kinds, KINDS, "--kinds", parser)
    args.strategies = names(args.strategies, list(STRATEGIES), "--strategies", parser)
    return args


if __name__ == "__main__":
    sys.exit(main())
