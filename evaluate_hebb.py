#!/usr/bin/env python
"""Evaluate Hebbian rules evolved by train_hebb.py (or by the original code).

    python evaluate_hebb.py --environment CarRacing-v0 --hebb_rule ABCD_lr --path_hebb heb_coeffs.dat \\
        --path_coev cnn_parameters.dat --init_weights uni
"""

import sys

from cli import INIT_CHOICES, RULES, evaluate_main, evaluation_parser
from es.files import load_dat


def build_parser():
    parser = evaluation_parser("evaluate_hebb.py", __doc__.splitlines()[0])
    parser.add_argument("--hebb_rule", default="ABCD_lr", choices=list(RULES), metavar="RULE",
                        help=f"the rule the coefficients were evolved for: {', '.join(RULES)}")
    parser.add_argument("--init_weights", default="uni", choices=list(INIT_CHOICES), metavar="INIT",
                        help=f"initial weights of every episode: {', '.join(INIT_CHOICES)}")
    parser.add_argument("--path_hebb", required=True, metavar="FILE", help="the .dat file of Hebbian coefficients")
    parser.add_argument("--path_coev", default=None, metavar="FILE",
                        help="the .dat file of CNN weights (pixel environments) or of co-evolved initial weights")
    return parser


def load_arrays(args) -> dict:
    arrays = {"coeffs": load_dat(args.path_hebb)}
    if args.path_coev is not None:
        role = "coevolved_initial_weights" if args.init_weights == "coevolve" else "CNN_parameters"
        arrays[role] = load_dat(args.path_coev)
    return arrays


def main(argv=None) -> int:
    return evaluate_main("hebbian", build_parser(), argv, load_arrays, "path_hebb")


if __name__ == "__main__":
    sys.exit(main())
