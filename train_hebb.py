#!/usr/bin/env python
"""Evolve synapse-specific Hebbian rules with OpenAI-ES (Najarro & Risi, NeurIPS 2020).

The weights start random every episode and change at every step by the evolved rules.

    python train_hebb.py --environment CarRacing-v0
    python train_hebb.py --environment CartPole-v1 --hebb_rule ABCD_lr --generations 20 --seed 1
    python train_hebb.py --environment CartPole-v1 --reservoir --reservoir_units 50 --generations 20 --seed 1
"""

import sys

from cli import train_main, training_parser


def build_parser():
    return training_parser("train_hebb.py", __doc__.splitlines()[0], "hebbian", folder="heb_coeffs")


def main(argv=None) -> int:
    return train_main("hebbian", build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
