"""experiments/seeds.py: several seeds of one configuration, their run folders, resume and refusals.

Real training runs (CartPole-v1, tiny budgets) through the real command line.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from es.files import read_json, read_metrics
from tests.extras import need

ROOT = Path(__file__).resolve().parent.parent
TRAINING = ["train_static.py", "--environment", "CartPole-v1", "--popsize", "4"]


def launch(*argv: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "experiments" / "seeds.py"), *argv], check=False, cwd=cwd,
                          capture_output=True, text=True, timeout=600)


def only_run(seed_folder: Path) -> Path:
    runs = [path for path in seed_folder.iterdir() if path.is_dir()]
    assert len(runs) == 1, runs
    return runs[0]


def comparable(run: Path) -> list[tuple]:
    return [(row["generation"], row["fitness_mean"], row["center_return"], row["env_steps"])
            for row in read_metrics(run / "metrics.csv")]


def test_seeds_run_resume_and_match_a_single_run(tmp_path):
    folder = tmp_path / "launch"
    first = launch("--seeds", "2", "--jobs", "2", "--", *TRAINING, "--generations", "1", "--folder", str(folder))
    assert first.returncode == 0, first.stdout + first.stderr
    runs = {seed: only_run(folder / f"seed{seed}") for seed in (1, 2)}
    for seed, run in runs.items():
        config = read_json(run / "config.json")
        assert config["run"]["seed"] == seed and config["run"]["threads"] == 1  # 2 jobs on this 2-core machine
        assert len(read_metrics(run / "metrics.csv")) == 1
    # the same launch with more generations resumes each seed's run in place
    again = launch("--seeds", "2", "--jobs", "2", "--", *TRAINING, "--generations", "2", "--folder", str(folder))
    assert again.returncode == 0, again.stdout + again.stderr
    assert {seed: only_run(folder / f"seed{seed}") for seed in (1, 2)} == runs
    # ... to the numbers of one uninterrupted run of that seed
    single = subprocess.run([sys.executable, "train_static.py", *TRAINING[1:], "--generations", "2", "--seed", "2",
                             "--threads", "1", "--folder", str(tmp_path / "single")], check=False, cwd=ROOT,
                            capture_output=True, text=True, timeout=600)
    assert single.returncode == 0, single.stderr
    assert comparable(runs[2]) == comparable(only_run(tmp_path / "single"))
    assert read_json(folder / "launch.json")["flags"][-3:] == ["2", "--folder", str(folder)]


def test_refusals_name_the_problem(tmp_path):
    folder = tmp_path / "launch"
    folder.mkdir()
    (folder / "launch.json").write_text('{"script": "train_static.py", "flags": ["--environment", "CartPole-v1", '
                                        '"--popsize", "4", "--folder", "x"]}')
    other = launch("--seeds", "2", "--", *TRAINING[:-1], "8", "--folder", str(folder))
    assert other.returncode == 2
    assert other.stderr.strip().splitlines() == [
        (f"seeds.py: error: {folder} holds a launch with other settings: --popsize 8 (the launch has 4); give the "
        "same settings to resume it (only --generations, --print_every, --threads, --backend, --ray_address, "
        "--logger, --wandb_project, --mlflow_uri, --mlflow_experiment may change) or use another --folder")]
    kind = launch("--", "train_hebb.py", "--environment", "CartPole-v1", "--folder", str(folder))
    assert kind.returncode == 2 and "holds a launch of train_static.py, not train_hebb.py" in kind.stderr
    seed = launch("--", *TRAINING, "--seed", "3", "--folder", str(tmp_path / "new"))
    assert seed.returncode == 2 and "--seed: set by the launcher" in seed.stderr
    no_folder = launch("--", *TRAINING)
    assert no_folder.returncode == 2 and "give train_static.py a --folder" in no_folder.stderr
    script = launch("--", "evaluate_static.py", "--folder", str(tmp_path / "new"))
    assert script.returncode == 2
    assert "must start with one of train_hebb.py, train_static.py, got evaluate_static.py" in script.stderr
    bad_flag = launch("--", *TRAINING, "--lr", "-1", "--folder", str(tmp_path / "new"))
    assert bad_flag.returncode == 2 and bad_flag.stderr.startswith("seeds.py: error: --lr must be a number > 0")
    for result in (kind, seed, no_folder, script, bad_flag):
        assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not (tmp_path / "new").exists()  # nothing was created


def test_dry_run_prints_one_command_per_seed_with_threads_sharing_the_cores(tmp_path):
    done = launch("--seeds", "3", "--first_seed", "7", "--jobs", "1", "--dry-run", "--", *TRAINING,
                  "--folder", str(tmp_path / "f"))
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    assert len(lines) == 3
    cores = len(os.sched_getaffinity(0))
    for seed, line in zip((7, 8, 9), lines):
        assert line.endswith(f"--seed {seed} --threads {cores} --folder {tmp_path / 'f' / f'seed{seed}'}")
    assert not (tmp_path / "f").exists()


def test_seeds_as_ray_tasks(tmp_path):
    need("ray")
    folder = tmp_path / "ray"
    done = launch("--seeds", "2", "--ray", "--", *TRAINING, "--generations", "1", "--folder", str(folder))
    assert done.returncode == 0, done.stdout + done.stderr
    for seed in (1, 2):
        run = only_run(folder / f"seed{seed}")
        assert read_json(run / "config.json")["run"]["seed"] == seed
        assert len(read_metrics(run / "metrics.csv")) == 1
