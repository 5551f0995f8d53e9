"""Run folders and files get portable names for any environment id, and the hints
printed at the end of a run work when pasted in another folder, outside the virtual environment.

A namespaced id (``Tests/Corridor-v0``, registered by ``tests.custom_env_module``, as ``ALE/Pong-v5``
is by ale-py) is trained from a data folder far from the repository, with the script given by path;
the printed "evaluate with" command is then pasted in yet another folder with a bare PATH.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from envs import EnvSettings
from envs.settings import LABEL_MAX
from tests.extras import need

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("environment, label", [
    ("CartPole-v1", "CartPole-v1"),  # the original's names, byte for byte
    ("AntBulletEnv-v0,HalfCheetahBulletEnv-v0", "AntBulletEnv-v0+HalfCheetahBulletEnv-v0"),
    ("ALE/Pong-v5", "ALE-Pong-v5"),
    ("tests.custom_env_module:Tests/Corridor-v0", "Tests-Corridor-v0"),
    ("ALE/Pong-v5, ALE/Breakout-v5", "ALE-Pong-v5+ALE-Breakout-v5"),
    ("my_envs:Odd Id*v0", "Odd-Id-v0"),
])
def test_the_environment_label_is_a_portable_file_name(environment, label):
    assert EnvSettings(environment=environment).label == label


def test_a_label_of_many_ids_keeps_names_short_and_apart():
    """Twenty ids make a label of 349 characters; a run folder's files hold it twice, in names of at most
    255 bytes."""
    many = [f"AntBulletEnv{index}-v0" for index in range(20)]
    labels = {EnvSettings(environment=",".join(ids)).label for ids in (many, many[::-1], many[:-1])}
    assert len(labels) == 3 and {len(label) for label in labels} == {LABEL_MAX}
    assert all(label.startswith("AntBulletEnv") and re.fullmatch(r".*-[0-9a-f]{8}", label) for label in labels)


def bare_shell() -> dict:
    """A new terminal: no virtual environment on PATH, the repository not importable."""
    return {"PATH": "/usr/bin:/bin", "HOME": os.environ.get("HOME", "/root"), "SDL_VIDEODRIVER": "dummy"}


def last_hint(output: str, prefix: str) -> str:
    return output.strip().splitlines()[-1].split(prefix, 1)[1]


@pytest.mark.parametrize("script", ["train_static.py", "train_hebb.py"])
def test_a_namespaced_id_trains_and_evaluates_through_the_printed_hint_in_another_folder(script, tmp_path):
    data, elsewhere = tmp_path / "data", tmp_path / "somewhere else"
    data.mkdir()
    elsewhere.mkdir()
    trained = subprocess.run(
        [sys.executable, str(ROOT / script), "--environment", "tests.custom_env_module:Tests/Corridor-v0",
         "--popsize", "4", "--generations", "2", "--threads", "1", "--seed", "3", "--folder", "runs"],
        cwd=data, capture_output=True, text=True, timeout=300)
    assert trained.returncode == 0, trained.stderr
    (run,) = (data / "runs").iterdir()
    assert run.name.endswith("_Tests-Corridor-v0_seed3")
    assert all("/" not in name and ":" not in name for name in os.listdir(run))
    assert any(name.startswith("Fitness_values_") and name.endswith("_Tests-Corridor-v0.npy")
               for name in os.listdir(run))
    evaluate = last_hint(trained.stdout, "evaluate with: ")
    assert shlex.split(evaluate)[1] == str(ROOT / script.replace("train", "evaluate"))
    evaluated = subprocess.run(["/bin/sh", "-c", evaluate], cwd=elsewhere, env=bare_shell(), capture_output=True,
                               text=True, timeout=300)
    assert evaluated.returncode == 0, evaluated.stderr
    assert "Corridor-v0" in evaluated.stdout and list(elsewhere.iterdir()) == []


def test_a_namespaced_atari_id_trains(tmp_path):
    need("atari")
    trained = subprocess.run(
        [sys.executable, str(ROOT / "train_static.py"), "--environment", "ALE/Pong-v5", "--popsize", "2",
         "--generations", "1", "--threads", "1", "--seed", "1", "--max_episode_steps", "5", "--folder", "runs"],
        cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert trained.returncode == 0, trained.stderr
    (run,) = (tmp_path / "runs").iterdir()
    assert run.name.endswith("_ALE-Pong-v5_seed1") and (run / "best.dat").is_file()
    evaluate = last_hint(trained.stdout, "evaluate with: ").replace("--episodes 10", "--episodes 1")
    evaluated = subprocess.run(["/bin/sh", "-c", evaluate], cwd=tmp_path, env=bare_shell(),
                               capture_output=True, text=True, timeout=300)
    assert evaluated.returncode == 0, evaluated.stderr
