"""The commands the scripts print for the user to run next: resume a run, evaluate its parameters."""

from __future__ import annotations

from pathlib import Path

from cli.config import TrainConfig

TRAIN_SCRIPTS = {"static": "train_static.py", "hebbian": "train_hebb.py"}
# role of a policy's exported array -> (evaluate script, its flag)
EVALUATE_FLAGS = {"weights": ("evaluate_static.py", "--path_weights"), "coeffs": ("evaluate_hebb.py", "--path_hebb"),
                  "CNN_parameters": ("evaluate_hebb.py", "--path_coev"),
                  "coevolved_initial_weights": ("evaluate_hebb.py", "--path_coev")}


def resume_hint(config: TrainConfig, run_dir: Path) -> str:
    return f"python {TRAIN_SCRIPTS[config.policy.kind]} --resume {run_dir}"


def evaluate_hint(config: TrainConfig, paths: dict[str, Path]) -> str:
    """The command that evaluates the parameter files ``paths`` (role -> file) over 10 episodes."""
    script = EVALUATE_FLAGS[next(iter(paths))][0]
    words = [f"python {script} --environment {config.env.environment}"]
    if config.policy.kind == "hebbian":
        words.append(f"--hebb_rule {config.policy.hebb_rule} --init_weights {config.policy.init_weights}")
    if config.policy.network != "default":
        words.append(f"--network {config.policy.network}")
    words += [f"{EVALUATE_FLAGS[role][1]} {path}" for role, path in paths.items()]
    return " ".join(words + ["--episodes 10"])
