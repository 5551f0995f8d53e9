#!/usr/bin/env python
"""Evolve synapse-specific Hebbian rules with OpenAI-ES (Najarro & Risi, NeurIPS 2020).

The weights start random every episode and change at every step by the evolved rules.

    python train_hebb.py --environment CarRacing-v0
    python train_hebb.py --environment CartPole-v1 --hebb_rule ABCD_lr --generations 20 --seed 1
    python train_hebb.py --environment CartPole-v1 --reservoir --reservoir_units 50 --generations 20 --seed 1
"""

import sys

from cli import DISTRIBUTIONS, INIT_CHOICES, RULES, train_main, training_parser
from cli.flags import add_reservoir_flags


def build_parser():
    parser = training_parser("train_hebb.py", __doc__.splitlines()[0], folder="heb_coeffs")
    parser.add_argument("--hebb_rule", default="ABCD_lr", choices=list(RULES), metavar="RULE",
                        help=f"Hebbian rule: {', '.join(RULES)}")
    parser.add_argument("--init_weights", default="uni", choices=list(INIT_CHOICES), metavar="INIT",
                        help=f"initial weights of every episode: {', '.join(INIT_CHOICES)} "
                             "(coevolve: evolved with the rules)")
    parser.add_argument("--distribution", default="normal", choices=list(DISTRIBUTIONS), metavar="DIST",
                        help="generation-0 coefficients (and CNN / co-evolved weights): normal N(0,1) "
                             "or uniform U(-1,1)")
    add_reservoir_flags(parser)
    return parser


def main(argv=None) -> int:
    return train_main("hebbian", build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
