"""Flag value types shared by the four scripts: each refuses a bad value in one line that names it."""

from __future__ import annotations

import argparse

import numpy as np

from cli.errors import say


def positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text}")
    return value


def positive_float(text: str) -> float:
    value = float(text)
    if not value > 0 or not np.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text}")
    return value


SEED_RANGE = (0, 2**31 - 1)


def threads_value(text: str) -> int:
    """-1: all cores; N >= 1 workers. The original ran 0 and -2 (any value <= 1 but -1) serially,
    so its command lines keep working: they mean 1, with a notice."""
    value = int(text)
    if value == 0 or value < -1:
        say(f"note: --threads {value} runs everything in this process, as the original did; that is --threads 1")
        return 1
    return value


def fraction(text: str) -> float:
    """A number in (0, 1]."""
    value = float(text)
    if not 0 < value <= 1:
        raise argparse.ArgumentTypeError(f"must be a number in (0, 1], got {text}")
    return value


def seed_value(text: str) -> int:
    value = int(text)
    low, high = SEED_RANGE
    if not low <= value <= high:
        raise argparse.ArgumentTypeError(f"must be a whole number from {low} to {high}, got {text}")
    return value


def non_empty(text: str) -> str:
    if not text.strip():
        raise argparse.ArgumentTypeError("is empty; give a path")
    return text


def flag_value(text: str | None) -> bool:
    """``--render`` alone, or the original's ``--render True`` / ``--render False``."""
    if text is None:
        return True
    lowered = text.strip().lower()
    if lowered in ("1", "true", "yes", "on"):
        return True
    if lowered in ("0", "false", "no", "off", ""):
        return False
    raise argparse.ArgumentTypeError(f"expected true or false, got {text!r}")


def add_network_flag(parser: argparse.ArgumentParser) -> None:
    """``--network`` of the static scripts: the original's network, or one of pytorch-es's."""
    from policies import NETWORKS

    parser.add_argument("--network", choices=tuple(NETWORKS), default="default",
                        help="default: the original's MLP (state vectors) or CNN (images); small: pytorch-es's "
                             "64-64 selu MLP (state vectors); lstm: pytorch-es's conv-LSTM on its 42x42 "
                             "normalised frames (images)")
