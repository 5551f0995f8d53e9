#!/usr/bin/env python
"""Evaluate static weights evolved by train_static.py (or by the original code).

    python evaluate_static.py --path_weights run/last.dat --episodes 10       # as the run recorded it
    python evaluate_static.py --environment CarRacing-v0 --path_weights weights.dat   # the original's files
"""

import sys

from cli import evaluate_main, evaluation_parser


def build_parser():
    return evaluation_parser("evaluate_static.py", __doc__.splitlines()[0], "static")


def main(argv=None) -> int:
    return evaluate_main("static", build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
