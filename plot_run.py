#!/usr/bin/env python
"""Overlay the learning curves of several training runs (their metrics.csv) in one picture.

    python plot_run.py weights/20250101-120000_CartPole-v1_seed1 weights/20250101-130000_CartPole-v1_seed2
    python plot_run.py weights/*CarRacing* -o carracing.png

Each run's own picture, with its min-max band, is the ``fitness.png`` training writes in its folder.
"""

from __future__ import annotations

import sys
from pathlib import Path

from cli import Parser, UserError
from cli.errors import say
from es import files
from es.outputs import check_output
from report import plots

DEFAULT_OUTPUT = "fitness_comparison.png"


def build_parser() -> Parser:
    parser = Parser(prog="plot_run.py", description=__doc__.splitlines()[0])
    parser.add_argument("run_dirs", nargs="+", metavar="RUN_DIR", help="run folders made by train_*.py")
    parser.add_argument("-o", "--output", default=DEFAULT_OUTPUT, metavar="PATH",
                        help=f"the picture to write, in the format its suffix names "
                             f"({', '.join(plots.FIGURE_SUFFIXES)}; "
                             f"default: {DEFAULT_OUTPUT}); never a file of a run folder")
    return parser


def read_run(run_dir: str) -> list[dict]:
    """The metrics rows of a run folder, checked to hold at least one generation."""
    path = Path(run_dir) / "metrics.csv"
    if not path.is_file():
        raise UserError(f"{run_dir}: no metrics.csv here (not a run folder, or no generation finished yet)")
    try:
        rows = files.read_metrics(path)
    except (OSError, ValueError) as error:  # a folder, a pipe, bytes that are not text
        raise UserError(f"{path}: cannot be read ({getattr(error, 'strerror', None) or error})") from None
    if not rows:
        raise UserError(f"{path} holds no generation yet")
    missing = [name for name in ("generation", "fitness_mean", "fitness_max", "fitness_min") if name not in rows[0]]
    if missing:
        raise UserError(f"{path} is not a metrics file of this tool (no column {', '.join(missing)})")
    try:
        plots.curves(rows)  # every value the picture reads is a number
    except (TypeError, ValueError) as error:  # TypeError: a row cut short
        raise UserError(f"{path} holds a value that is not a number ({error}); it is not metrics.csv as the run "
                        "wrote it") from None
    return rows


def labels(run_dirs: list[str]) -> list[str]:
    """Folder names, or the paths as given where two runs share a name."""
    names = [Path(run_dir).resolve().name for run_dir in run_dirs]
    return names if len(set(names)) == len(names) else list(run_dirs)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        inputs = [Path(run_dir) / "metrics.csv" for run_dir in args.run_dirs]
        check_output("-o", args.output, plots.FIGURE_SUFFIXES, inputs)
        runs = [(label, read_run(run_dir)) for label, run_dir in zip(labels(args.run_dirs), args.run_dirs)]
        plots.save_comparison(Path(args.output), runs)
    except (UserError, ValueError) as error:  # ValueError: a refused output
        print(f"plot_run.py: error: {error}", file=sys.stderr)
        return 2
    except OSError as error:
        print(f"plot_run.py: error: cannot write {args.output}: {error.strerror or error}", file=sys.stderr)
        return 2
    say(f"wrote {args.output} ({len(runs)} runs)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
