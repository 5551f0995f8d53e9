"""The commands the scripts print for the user to run next: resume a run, evaluate its parameters.

A printed command must work when pasted into any shell, in any folder: it names the interpreter that
is running (``sys.executable``, so it works outside an activated virtual environment too) and the
script by its absolute path, and every word is shell-quoted (a ``--folder "my runs"`` stays one word).
The evaluate command is short: the weight file alone, since the evaluate scripts take the rest from
the run folder's config.json and the files beside it (``cli.evaluate``).
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

from cli.config import TRAIN_SCRIPTS, TrainConfig
from policies import KINDS
from policies.plugin import FileFlag

ROOT = Path(__file__).resolve().parent.parent

EVALUATE_SCRIPTS = {name: kind.scripts[1] for name, kind in KINDS.items()}
# the front end's file, whatever the kind: a --reservoir_evolve run's evolved hyperparameters
RESERVOIR_FILE = FileFlag("--path_reservoir", ("reservoir",), "the evolved reservoir hyperparameters of a "
                                                              "--reservoir_evolve run")
# the evaluate scripts' flag of each file role a policy exports (``Policy.roles``), from the kinds' entries
EVALUATE_FLAGS = {role: file.flag for kind in KINDS.values() for file in (*kind.files, RESERVOIR_FILE)
                  for role in file.roles}

__all__ = ["EVALUATE_FLAGS", "EVALUATE_SCRIPTS", "RESERVOIR_FILE", "TRAIN_SCRIPTS", "command", "evaluate_hint",
           "resume_hint", "script_path"]


def script_path(name: str) -> str:
    """The project's script ``name``, by its absolute path."""
    return str(ROOT / name)


def command(script: str, *words: object) -> str:
    """The project's script ``script`` with ``words``, runnable from any folder (paths: absolute)."""
    return shlex.join([sys.executable or "python", script_path(script),
                       *(str(word.absolute()) if isinstance(word, Path) else str(word) for word in words)])


def resume_hint(config: TrainConfig, run_dir: Path) -> str:
    return command(TRAIN_SCRIPTS[config.policy.kind], "--resume", Path(run_dir))


def evaluate_hint(config: TrainConfig, weight_file: Path) -> str:
    """The command that evaluates a run's weight file (the rest comes from its folder) over 10 episodes."""
    kind = config.policy.kind
    return command(EVALUATE_SCRIPTS[kind], KINDS[kind].files[0].flag, Path(weight_file), "--episodes", 10)
