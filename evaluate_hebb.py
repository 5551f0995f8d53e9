#!/usr/bin/env python
"""Evaluate Hebbian rules evolved by train_hebb.py (or by the original code).

    python evaluate_hebb.py --path_hebb run/last_coeffs.dat --episodes 10      # as the run recorded it
    python evaluate_hebb.py --environment CarRacing-v0 --hebb_rule ABCD_lr --path_hebb heb_coeffs.dat \\
        --path_coev cnn_parameters.dat --init_weights uni                      # the original's files
"""

import sys

from cli import evaluate_main, evaluation_parser


def build_parser():
    return evaluation_parser("evaluate_hebb.py", __doc__.splitlines()[0], "hebbian")


def main(argv=None) -> int:
    return evaluate_main("hebbian", build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
