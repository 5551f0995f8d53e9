"""Evolved reservoirs for meta-reinforcement learning (ER-MRL; Léger, Hamon, Nisioti, Hinaut and
Moulin-Frier, EvoApplications 2024, arXiv 2312.06695), on maintained libraries.

An outer loop (optuna) evolves the hyperparameters of random recurrent networks, reservoirs; an inner
loop trains a PPO agent (stable-baselines3) from scratch on the reservoir's state instead of the
observation. Upstream spec §8 and §9.3 describe the original; README "Evolved reservoirs (ER-MRL)"
says what changed.

    esn.py          the echo state network: reservoirpy 0.4 with reservoirpy 0.3's semantics (reset / step
                    on one input); its random draws, which policies.reservoir rescales per member
    wrappers.py     the Gymnasium wrappers of the original, one concern each
    experiments.py  search space, environment presets, target and random returns, the normalised score
    training.py     the inner loop: PPO with SB3's defaults, and a trial's fitness
    study.py        optuna: samplers, journal storage, study names, recorded settings
    commands.py     the six scripts of scripts/, and their one-line errors

This module imports nothing heavy, so that a script can say how to install the optional extra
before anything fails to import.
"""

from __future__ import annotations

import importlib

# import name -> distribution name, for the scripts (tensorboard only for the test scripts' logs)
EXTRA_MODULES = {"reservoirpy": "reservoirpy", "stable_baselines3": "stable-baselines3", "optuna": "optuna",
                 "cmaes": "cmaes"}
TEST_MODULES = {**EXTRA_MODULES, "tensorboard": "tensorboard"}
INSTALL_HINT = "pip install -r requirements-reservoirs.txt (or pip install -e .[reservoirs])"
# ER-MRL's search bounds of each reservoir hyperparameter (its --min_* / --max_* defaults), in its scripts'
# order: the scripts' defaults, and the range policies.reservoir maps evolved genes into
SEARCH_BOUNDS: dict[str, tuple[float, float]] = {"sr": (1e-4, 1e2), "lr": (1e-2, 1.0), "iss": (1e-1, 10.0)}


def missing_packages(modules: dict[str, str]) -> list[str]:
    """The distributions of ``modules`` that cannot be imported."""
    missing = []
    for module, distribution in modules.items():
        try:
            importlib.import_module(module)
        except ImportError:
            missing.append(distribution)
    return missing


def run_script(script: str, argv: list[str] | None = None) -> int:
    """Entry point of ``scripts/<script>.py``: one line and exit code 2 if the optional extra is missing.

    A SIGTERM (what cluster schedulers send) stops a script as Ctrl-C does, so that optuna marks the
    trial it interrupts as failed instead of leaving it running in the journal forever.
    """
    import signal
    import sys

    signal.signal(signal.SIGTERM, _interrupt)
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:  # a background job of a script: Ctrl-C's meaning back
        signal.signal(signal.SIGINT, signal.default_int_handler)
    missing = missing_packages(TEST_MODULES if script.startswith("test") else EXTRA_MODULES)
    if missing:
        print(f"{script}.py: error: the ER-MRL scripts need {', '.join(missing)}, not installed here; {INSTALL_HINT}",
              file=sys.stderr)
        return 2
    from reservoirs.commands import main

    return main(script, argv)


def _interrupt(signum, frame):
    raise KeyboardInterrupt
