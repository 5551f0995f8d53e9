"""Flag value types shared by the four scripts: each refuses a bad value in one line that names it."""

from __future__ import annotations

import argparse

import numpy as np


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


def threads_value(text: str) -> int:
    value = int(text)
    if value == 0 or value < -1:
        raise argparse.ArgumentTypeError(f"must be -1 (all cores) or a number of workers >= 1, got {text}")
    return value


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
