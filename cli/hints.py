"""The commands the scripts print for the user to run next: resume a run, evaluate its parameters.

A printed command must work when pasted into any shell, in any folder: it names the interpreter
that is running (``sys.executable``, so it works outside an activated virtual environment too),
the script and the run's files by absolute paths, and every word is shell-quoted (a
``--folder "my runs"`` stays one word).
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

from cli.config import TrainConfig

ROOT = Path(__file__).resolve().parent.parent
TRAIN_SCRIPTS = {"static": "train_static.py", "hebbian": "train_hebb.py"}
EVALUATE_SCRIPTS = {"static": "evaluate_static.py", "hebbian": "evaluate_hebb.py"}
# role of a policy's exported array -> the evaluate scripts' flag for its file
EVALUATE_FLAGS = {"weights": "--path_weights", "coeffs": "--path_hebb", "CNN_parameters": "--path_coev",
                  "coevolved_initial_weights": "--path_coev", "reservoir": "--path_reservoir"}


def command(script: str, *words: object) -> str:
    """The project's script ``script`` with ``words``, runnable from any folder (paths: absolute)."""
    return shlex.join([sys.executable or "python", str(ROOT / script),
                       *(str(word.absolute()) if isinstance(word, Path) else str(word) for word in words)])


def resume_hint(config: TrainConfig, run_dir: Path) -> str:
    return command(TRAIN_SCRIPTS[config.policy.kind], "--resume", Path(run_dir))


def evaluate_hint(config: TrainConfig, paths: dict[str, Path]) -> str:
    """The command that evaluates the parameter files ``paths`` (role -> file) over 10 episodes."""
    words: list[object] = ["--environment", config.env.environment]
    if config.policy.kind == "hebbian":
        words += ["--hebb_rule", config.policy.hebb_rule, "--init_weights", config.policy.init_weights]
    if config.policy.network != "default":
        words += ["--network", config.policy.network]
    words += reservoir_words(config)
    for role, path in paths.items():
        words += [EVALUATE_FLAGS[role], Path(path)]
    return command(EVALUATE_SCRIPTS[config.policy.kind], *words, "--episodes", 10)


def reservoir_words(config: TrainConfig) -> list[object]:
    """The reservoir flags of the evaluate scripts, for a run with ``--reservoir`` (evolved hyperparameters
    come from their file instead)."""
    policy = config.policy
    if not policy.reservoir:
        return []
    words: list[object] = ["--reservoir", "--reservoir_units", policy.reservoir_units]
    if not policy.reservoir_evolve:
        words += ["--reservoir_lr", policy.reservoir_lr, "--reservoir_sr", policy.reservoir_sr,
                  "--reservoir_iss", policy.reservoir_iss]
    return words + ["--reservoir_seed", policy.reservoir_seed]
