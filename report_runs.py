#!/usr/bin/env python
"""Compare groups of training runs with rliable's statistics: IQM and mean with bootstrap CIs, performance
profiles, probability of improvement (Agarwal et al. 2021).

    python report_runs.py --group static='runs/cartpole_static' --group hebbian='runs/cartpole_hebbian'
    python report_runs.py --group a='runs/a/*' --group b='runs/b/*' --score best --out runs/report_ab

A group is NAME=PATHS: run folders, globs of them (quoted, or expanded by the shell), or folders holding
run folders (as experiments/seeds.py writes them), separated by commas. Each run is reduced to one score
(--score; report/stats.py says how), and the groups are compared on one environment. The table is printed
and written, with the plot, to --out: summary.md, summary.csv, improvement.csv, scores.csv, report.png.
Needs the statistics extra: pip install -r requirements-stats.txt
"""

from __future__ import annotations

import sys
from pathlib import Path

from cli import Parser
from cli.flags import positive_int, seed_value
from es.outputs import run_folder_of
from report import stats
from settings import SEED_RANGE


def build_parser() -> Parser:
    parser = Parser(prog="report_runs.py", description=__doc__.splitlines()[0])
    parser.add_argument("--group", action="append", default=[], metavar="NAME=PATHS", required=True,
                        help="a configuration's run folders (given once per group)")
    parser.add_argument("--score", choices=list(stats.SCORES), default="final",
                        help="final: the last centre's return; best: the best centre's; "
                             + "; ".join(f"{score}: {name}" for score, name in stats.EVALUATIONS.items()))
    parser.add_argument("--environment", default=None, metavar="ID",
                        help=f"with --score {' or '.join(stats.EVALUATIONS)}: the environment of the evaluation file "
                             "to score (default: all)")
    parser.add_argument("--out", type=Path, default=Path("runs/report"), metavar="DIR", help="where the files go")
    parser.add_argument("--reps", type=positive_int, default=stats.DEFAULT_REPS, help="bootstrap replications")
    parser.add_argument("--seed", type=seed_value, default=0,
                        help="seed of the bootstrap: a whole number from {} to {} (default: 0)".format(*SEED_RANGE))
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    run = run_folder_of(args.out.resolve() / "summary.md")
    if run is not None:  # its files would go among a run's, and a second report would replace them
        print(f"report_runs.py: error: --out {args.out} is {'in ' if run != args.out.resolve() else ''}the run folder "
              f"{run}; give the report a folder of its own", file=sys.stderr)
        return 2
    if not stats.available():
        print(f"report_runs.py: error: the statistics need rliable, which is not installed; install it with: "
              f"{stats.INSTALL_HINT}", file=sys.stderr)
        return 2
    try:
        result = stats.report(args.group, args.out, args.score, args.environment, args.reps, args.seed)
    except (stats.StatsError, OSError) as error:
        print(f"report_runs.py: error: {error}", file=sys.stderr)
        return 2
    print(result.markdown, end="")
    print(f"written: {args.out}/summary.md, summary.csv, improvement.csv, scores.csv, report.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
