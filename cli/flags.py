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


RESERVOIR_FLAGS = ("reservoir_units", "reservoir_lr", "reservoir_sr", "reservoir_iss", "reservoir_seed")


def add_reservoir_flags(parser: argparse.ArgumentParser, evaluation: bool = False) -> None:
    """``--reservoir`` and its settings (``policies.reservoir``); values are checked by ``PolicySettings``.

    Training has ``--reservoir_evolve``; evaluation reads evolved hyperparameters from ``--path_reservoir``,
    and takes the whole reservoir from the run folder's config.json when ``--reservoir`` is not given."""
    from policies import PolicySettings
    from policies.reservoir import BOUNDS

    group = parser.add_argument_group("reservoir front end (ER-MRL's echo state network before the network)")
    add = group.add_argument
    add("--reservoir", action="store_true",
        help="the network reads the state of a random reservoir (ER-MRL's leaky echo state network, reset every "
             "episode) that reads the observation; not for pixels; needs reservoirpy "
             "(pip install -r requirements-reservoirs.txt)"
             + ("; default: as the run folder's config.json says" if evaluation else ""))
    add("--reservoir_units", type=int, default=PolicySettings.reservoir_units, metavar="N",
        help="its neurons (ER-MRL's --units)")
    add("--reservoir_lr", type=float, default=PolicySettings.reservoir_lr, metavar="LR",
        help="its leak rate, in (0, 1]" + ("" if evaluation else "; with --reservoir_evolve where evolution starts"))
    add("--reservoir_sr", type=float, default=PolicySettings.reservoir_sr, metavar="SR",
        help="the spectral radius of its recurrent weights")
    add("--reservoir_iss", type=float, default=PolicySettings.reservoir_iss, metavar="ISS",
        help="the scaling of its input weights")
    if evaluation:
        add("--reservoir_seed", type=seed_value, default=None,
            help="the seed its matrices were drawn with: the training run's (its config.json's reservoir_seed)")
        add("--path_reservoir", default=None, metavar="FILE",
            help="the evolved reservoir hyperparameters of a --reservoir_evolve run (best_reservoir.dat, "
                 "last_reservoir.dat)")
    else:
        add("--reservoir_seed", type=seed_value, default=None,
            help="the seed of its random matrices (default: the run's --seed)")
        add("--reservoir_evolve", action="store_true",
            help="evolve its leak rate, spectral radius and input scaling with the network: three more parameters, "
                 "log-scale within ER-MRL's bounds "
                 + ", ".join(f"{name} [{low:g}, {high:g}]" for name, (low, high) in BOUNDS.items()))
