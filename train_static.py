#!/usr/bin/env python
"""Evolve the weights of a static network with OpenAI-ES (the baseline of Najarro & Risi 2020).

    python train_static.py --environment CarRacing-v0
    python train_static.py --environment CartPole-v1 --generations 20 --popsize 32 --seed 1
    python train_static.py --environment CartPole-v1 --reservoir --reservoir_evolve --generations 20 --seed 1
    python train_static.py --environment PongDeterministic-v4 --network lstm --popsize 40 --lr 0.1 --sigma 0.05
"""

import sys

from cli import train_main, training_parser


def build_parser():
    return training_parser("train_static.py", __doc__.splitlines()[0], "static", folder="weights")


def main(argv=None) -> int:
    return train_main("static", build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
