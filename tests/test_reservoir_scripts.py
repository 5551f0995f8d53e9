"""ER-MRL's command lines (scripts/) with tiny budgets: one 2048-step PPO rollout per lifetime, the least
PPO trains (SB3's n_steps), on CartPole-v1, Pendulum-v1 and MuJoCo.

Covers: a study of 2 trials resumed to 4 from its journal; the same seeds giving the same trials and
returns; test.py training on the study's best parameters (and --training_timesteps); the multi-reservoir
and generalisation scripts with their tests; a trial without a finished episode pruned; a study
interrupted with Ctrl-C; two processes sharing one study; bad input and a missing extra in one line,
exit code 2, nothing written.

Most commands run in this process through ``reservoirs.commands.main`` (the same code as the scripts,
without an interpreter and torch start-up each); the ones that must be processes run as such.
Skipped where the optional extra is not installed, except the check that the scripts then say how to
install it.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cli.hints import command
from tests.extras import need

ROOT = Path(__file__).resolve().parent.parent
ENV = {**os.environ, "SDL_VIDEODRIVER": "dummy", "MUJOCO_GL": "egl", "PYTHONUNBUFFERED": "1"}
STEPS = "2048"
CARTPOLE = ("--env_id", "CartPole-v1", "--h_test", "t", "--training_steps", STEPS, "--nb_seeds", "1",
            "--sampler", "Cmaes", "--sampler_seed", "3")
CARTPOLE_JOURNAL = "optuna-journal_CartPole-v1_t_2k_steps.log"


def extra():
    need("reservoirs")
    import optuna

    return optuna


@contextlib.contextmanager
def working_folder(folder: Path):
    previous = Path.cwd()
    os.chdir(folder)
    try:
        yield
    finally:
        os.chdir(previous)


def run_in(folder: Path, script: str, *args: str) -> tuple[int, str, str]:
    """``scripts/<script>.py args`` in this process, in ``folder``: exit code, stdout, stderr."""
    import torch

    from reservoirs.commands import main

    out, err = io.StringIO(), io.StringIO()
    threads = torch.get_num_threads()  # main() sets one thread; the other test files expect the default
    with working_folder(folder), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(script, list(args))
        except SystemExit as stop:  # argparse
            code = stop.code
        finally:
            torch.set_num_threads(threads)
    return code, out.getvalue(), err.getvalue()


def run_script(folder: Path, script: str, *args: str, **options) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, str(ROOT / "scripts" / f"{script}.py"), *args], cwd=folder, env=ENV,
                            text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, **options)


def load(folder: Path, journal: str, name: str):
    optuna = extra()
    from reservoirs.study import open_journal

    return optuna.load_study(study_name=name, storage=open_journal(folder / journal))


def finished(study) -> list[tuple[int, dict, float]]:
    return [(trial.number, trial.params, trial.value) for trial in study.trials if trial.state.name == "COMPLETE"]


@pytest.fixture(scope="module")
def evolved(tmp_path_factory):
    """evolve_res.py, 2 trials, then the same command again: the study goes on from its journal."""
    extra()
    folder = tmp_path_factory.mktemp("evolve_res")
    first = run_in(folder, "evolve_res", *CARTPOLE, "--nb_trials", "2")
    after_two = finished(load(folder, CARTPOLE_JOURNAL, "CartPole-v1_t_2k_steps"))
    second = run_in(folder, "evolve_res", *CARTPOLE, "--nb_trials", "2")
    return folder, first, after_two, second


def test_study_resumes_from_its_journal(evolved):
    folder, first, after_two, second = evolved
    assert first[0] == 0 and second[0] == 0, (first, second)
    assert "0 trials so far" in first[1] and "2 trials so far" in second[1]
    assert [number for number, *_ in after_two] == [0, 1]
    after_four = finished(load(folder, CARTPOLE_JOURNAL, "CartPole-v1_t_2k_steps"))
    assert [number for number, *_ in after_four] == [0, 1, 2, 3]
    assert after_four[:2] == after_two
    assert all(set(params) == {"sr", "lr"} for _, params, _ in after_four)  # --fixed_iss True: iss is 1.0
    assert len({params["sr"] for _, params, _ in after_four}) == 4  # the resumed sampler draws new points
    assert "trial 1 | fitness" in first[1]
    assert f"test it with: {command('scripts/test.py', '--env_id', 'CartPole-v1')}" in first[1]


def test_same_seeds_same_trials_and_returns(evolved, tmp_path):
    """A second study from scratch, same flags and seeds: the same parameters and the same fitness."""
    _, _, after_two, _ = evolved
    code, _, err = run_in(tmp_path, "evolve_res", *CARTPOLE, "--nb_trials", "2")
    assert code == 0, err
    assert finished(load(tmp_path, CARTPOLE_JOURNAL, "CartPole-v1_t_2k_steps")) == after_two


def test_test_script_trains_on_the_best_parameters(evolved):
    folder, *_ = evolved
    code, out, err = run_in(folder, "test", "--env_id", "CartPole-v1", "--h_test", "t", "--HP_training_steps", STEPS,
                            "--training_timesteps", STEPS)
    assert code == 0, err
    study = load(folder, CARTPOLE_JOURNAL, "CartPole-v1_t_2k_steps")
    summary = json.loads((folder / "models" / "CartPole-v1_t" / "test_2k_steps_seed_0.json").read_text())
    assert (summary["trial"], summary["params"], summary["fitness"]) == (study.best_trial.number, study.best_params,
                                                                         study.best_value)
    assert summary["reservoirs"] == [{"units": 100, "leak_rate": study.best_params["lr"],
                                      "spectral_radius": study.best_params["sr"], "input_scaling": 1.0}]
    models = ["PPO", "RES_PPO_0.0003", "RES_PPO_0.0001"]
    assert list(summary["models"]) == models
    for model in models:
        assert (folder / "models" / "CartPole-v1_t" / f"{model}_2k_steps_seed_0.zip").is_file()
        assert list((folder / "logs" / "CartPole-v1_t").glob(f"{model}_2k_steps_seed_0_1/events.out.tfevents.*"))
    assert f"best trial {study.best_trial.number}" in out


def test_other_settings_cannot_join_a_study(evolved):
    folder, *_ = evolved
    journal = (folder / CARTPOLE_JOURNAL).read_bytes()
    code, out, err = run_in(folder, "evolve_res", *CARTPOLE, "--nb_trials", "1", "--units", "50")
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "was evolved with other settings: units 100 (this command: 50)" in err
    assert (folder / CARTPOLE_JOURNAL).read_bytes() == journal


def test_multi_reservoirs_evolve_and_test(tmp_path):
    extra()
    common = ("--env_id", "Pendulum-v1", "--h_test", "m", "--nb_res", "2")
    code, out, err = run_in(tmp_path, "evolve_multi_res", *common, "--training_steps", STEPS, "--nb_trials", "1",
                            "--nb_seeds", "1", "--units", "10", "--skip_c", "True", "--sampler_seed", "0")
    assert code == 0, err
    study = load(tmp_path, "optuna-journal_Pendulum-v1_2_m_2k_steps.log", "Pendulum-v1_2_m_2k_steps")
    assert sorted(study.best_params) == ["iss_1", "iss_2", "lr_1", "lr_2", "sr_1", "sr_2"]
    code, out, err = run_in(tmp_path, "test_multi_res", *common, "--HP_training_steps", STEPS,
                            "--training_steps", STEPS)
    assert code == 0, err
    summary = json.loads((tmp_path / "models" / "Pendulum-v1_m" / "test_2k_steps_seed_0.json").read_text())
    assert list(summary["models"]) == ["PPO", "RES_PPO_0.0003", "RES_PPO_0.0001", "RES_PPO_0.00005"]
    assert summary["skip_c"] is True  # from the study: the original's test_multi_res.py had no --skip_c
    assert [one["input_scaling"] for one in summary["reservoirs"]] == [study.best_params["iss_1"],
                                                                       study.best_params["iss_2"]]


def test_generalization_evolves_on_two_tasks_and_tests_on_a_third(tmp_path):
    extra()
    code, out, err = run_in(tmp_path, "evolve_generalization", "--env_type", "Ant_Swimmer", "--h_test", "g",
                            "--nb_res", "2", "--training_timesteps", STEPS, "--nb_trials", "1", "--nb_seeds", "1",
                            "--units", "10", "--sampler", "Random", "--fixed_iss", "True", "--sampler_seed", "0")
    assert code == 0, err
    assert "Ant-v4: normalised score" in out and "Swimmer-v4: normalised score" in out
    study = load(tmp_path, "optuna-journal_Ant_Swimmer_2_g_2k_steps.log", "Ant_Swimmer_2_g_2k_steps")
    assert sorted(study.best_params) == ["lr_1", "lr_2", "sr_1", "sr_2"]
    code, out, err = run_in(tmp_path, "test_generalization", "--env_id", "HalfCheetah-v4", "--HP_env_type",
                            "Ant_Swimmer", "--h_test", "g", "--nb_res", "2", "--HP_training_steps", STEPS,
                            "--training_steps", STEPS)
    assert code == 0, err
    summary = json.loads((tmp_path / "models" / "HalfCheetah-v4_g" / "test_2k_steps_seed_0.json").read_text())
    assert list(summary["models"]) == ["PPO", "RES_PPO_0.0003"]
    assert [one["input_scaling"] for one in summary["reservoirs"]] == [1.0, 1.0]


def test_trial_without_a_finished_episode_is_pruned(tmp_path):
    optuna = extra()
    code, out, err = run_in(tmp_path, "evolve_res", "--env_id", "tests.reservoir_test_envs:TestLongCorridor-v0",
                            "--h_test", "p", "--training_steps", STEPS, "--nb_trials", "1", "--nb_seeds", "1",
                            "--sampler", "Tpe", "--units", "10")
    assert code == 0, err
    assert ("trial 0 pruned: no episode of tests.reservoir_test_envs:TestLongCorridor-v0 finished within 2048 "
            "training steps (seed 0); give more --training_steps") in out
    study = load(tmp_path, "optuna-journal_tests.reservoir_test_envs:TestLongCorridor-v0_p_2k_steps.log",
                 "tests.reservoir_test_envs:TestLongCorridor-v0_p_2k_steps")
    assert [trial.state for trial in study.trials] == [optuna.trial.TrialState.PRUNED]
    code, out, err = run_in(tmp_path, "test", "--env_id", "tests.reservoir_test_envs:TestLongCorridor-v0",
                            "--h_test", "p", "--HP_training_steps", STEPS)
    assert code == 2 and len(err.splitlines()) == 1 and "has no finished trial yet" in err, err


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_interrupted_study_keeps_its_trials(tmp_path, stop):
    """Ctrl-C, or a scheduler's SIGTERM, during a trial: it is marked failed in the journal, exit code 130."""
    extra()
    process = run_script(tmp_path, "evolve_res", *CARTPOLE, "--nb_trials", "3", start_new_session=True)
    lines = []
    for line in process.stdout:
        lines.append(line)
        if line.startswith("trial 0 | sr"):
            time.sleep(1)
            os.killpg(process.pid, stop)
            break
    _, err = process.communicate(timeout=120)
    assert process.returncode == 130, (lines, err)
    assert "stopped; the finished trials are in optuna-journal_CartPole-v1_t_2k_steps.log" in err
    study = load(tmp_path, CARTPOLE_JOURNAL, "CartPole-v1_t_2k_steps")
    assert [trial.state.name for trial in study.trials] == ["FAIL"]


def test_two_processes_share_one_study(tmp_path):
    extra()
    args = ("--env_id", "CartPole-v1", "--h_test", "shared", "--training_steps", STEPS, "--nb_seeds", "1",
            "--nb_trials", "1", "--sampler", "Random", "--units", "20")
    processes = [run_script(tmp_path, "evolve_res", *args) for _ in range(2)]
    for process in processes:
        out, err = process.communicate(timeout=300)
        assert process.returncode == 0, err
    study = load(tmp_path, "optuna-journal_CartPole-v1_shared_2k_steps.log", "CartPole-v1_shared_2k_steps")
    assert [number for number, *_ in finished(study)] == [0, 1]


BAD_INPUT = {
    "unknown sampler": (("evolve_res", *CARTPOLE[:-4], "--sampler", "Grid", "--nb_trials", "1"),
                        "argument --sampler: invalid choice: 'Grid' (choose from "),
    "unknown env type": (("evolve_generalization", "--env_type", "Ant_Moon", "--h_test", "g", "--nb_res", "2",
                          "--training_steps", STEPS, "--nb_trials", "1", "--sampler", "Cmaes"),
                         "unknown --env_type 'Ant_Moon'; valid: Ant_Swimmer, Ant_Cheetah"),
    "negative budget": (("evolve_res", *CARTPOLE[:4], "--training_steps", "-5", "--nb_trials", "1", "--sampler", "Tpe"),
                        "argument --training_steps/--training_timesteps: must be a whole number >= 1, got -5"),
    "no trials": (("evolve_res", *CARTPOLE, "--nb_trials", "0"), "argument --nb_trials: must be a whole number >= 1"),
    "unknown environment": (("evolve_res", "--env_id", "CartPol-v1", *CARTPOLE[2:], "--nb_trials", "1"),
                            "unknown environment 'CartPol-v1'; did you mean CartPole-v1"),
    "empty range": (("evolve_res", *CARTPOLE, "--nb_trials", "1", "--min_sr", "10", "--max_sr", "1"),
                    "--min_sr 10.0 and --max_sr 1.0: need 0 < min <= max"),
    "no velocities known": (("evolve_res", "--env_id", "Acrobot-v1", *CARTPOLE[2:], "--nb_trials", "1", "--del_obs"),
                            "--del_obs knows the velocities of CartPole, MountainCar"),
    "target below random": (("evolve_generalization", "--env_type", "Ant-v4,HumanoidStandup-v4", "--h_test", "g",
                             "--nb_res", "1", "--training_steps", STEPS, "--nb_trials", "1", "--sampler", "Cmaes"),
                            "no usable episodic random return below the target for HumanoidStandup-v4"),
    "no journal": (("test", "--env_id", "CartPole-v1", "--h_test", "nothing"),
                   "no journal optuna-journal_CartPole-v1_nothing_300k_steps.log in"),
    "not a bool": (("evolve_res", *CARTPOLE, "--nb_trials", "1", "--skip_c", "maybe"),
                   "argument --skip_c: expected true or false, got 'maybe'"),
    "negative sampler seed": (("evolve_res", *CARTPOLE, "--nb_trials", "1", "--sampler_seed", "-1"),
                              "argument --sampler_seed: must be a whole number from 0 to 2147483647, got -1"),
    "seed too large": (("test", "--env_id", "CartPole-v1", "--h_test", "nothing", "--seed", "4294967296"),
                       "argument --seed: must be a whole number from 0 to 2147483647"),
}


def test_a_corrupt_journal_is_named_and_left_as_it_was(evolved, tmp_path):
    """A line that is not JSON, in the middle or last: refused before optuna reads or appends to it."""
    extra()
    journal = evolved[0] / CARTPOLE_JOURNAL
    lines = journal.read_bytes().splitlines(keepends=True)
    for corrupt in (b"".join(lines[:1] + [b"garbage{{\n"] + lines[1:]), b"".join(lines) + b"garbage{{\n"):
        copy = tmp_path / journal.name
        copy.write_bytes(corrupt)
        for argv in (("evolve_res", *CARTPOLE, "--nb_trials", "1"),
                     ("test", *CARTPOLE[:4], "--HP_training_steps", STEPS)):
            code, out, err = run_in(tmp_path, *argv)
            assert code == 2 and len(err.splitlines()) == 1 and f"the journal {journal.name} is corrupt" in err, err
            assert copy.read_bytes() == corrupt


@pytest.mark.parametrize("case", BAD_INPUT)
def test_bad_input_is_one_line_and_exit_2(case, tmp_path):
    extra()
    argv, message = BAD_INPUT[case]
    code, out, err = run_in(tmp_path, *argv)
    assert code == 2 and len(err.splitlines()) == 1, err
    assert err.startswith(f"{argv[0]}.py: error: ") and message in err, err
    assert list(tmp_path.iterdir()) == []  # no journal, no folder


def test_missing_extra_says_how_to_install_it(tmp_path):
    """Runs on every install: the extra's packages are hidden where they are installed."""
    for module in ("reservoirpy", "stable_baselines3", "optuna", "cmaes"):
        hidden = tmp_path / "hide" / module
        hidden.mkdir(parents=True)
        (hidden / "__init__.py").write_text(f"raise ImportError('{module} hidden by the test')\n")
    process = subprocess.run([sys.executable, str(ROOT / "scripts" / "evolve_res.py"), "--help"], cwd=tmp_path,
                             env={**ENV, "PYTHONPATH": str(tmp_path / "hide")}, capture_output=True, text=True,
                             timeout=120)
    assert process.returncode == 2 and process.stdout == "", process
    assert process.stderr.splitlines() == [
        "evolve_res.py: error: the ER-MRL scripts need reservoirpy, stable-baselines3, optuna, cmaes, not installed "
        "here; "
        "pip install -r requirements-reservoirs.txt (or pip install -e .[reservoirs])"]
