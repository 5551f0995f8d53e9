#!/usr/bin/env python
"""Evaluate static weights evolved by train_static.py (or by the original code).

    python evaluate_static.py --environment CarRacing-v0 --path_weights weights.dat
    python evaluate_static.py --environment CartPole-v1 --path_weights run/best.dat --episodes 10
"""

import sys

from cli import evaluate_main, evaluation_parser
from es.files import load_dat


def build_parser():
    parser = evaluation_parser("evaluate_static.py", __doc__.splitlines()[0])
    parser.add_argument("--path_weights", required=True, metavar="FILE",
                        help="the .dat file of evolved weights")
    return parser


def load_arrays(args) -> dict:
    return {"weights": load_dat(args.path_weights)}


def main(argv=None) -> int:
    return evaluate_main("static", build_parser(), argv, load_arrays, "path_weights")


if __name__ == "__main__":
    sys.exit(main())
