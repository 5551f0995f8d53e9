"""The four command lines with small budgets (CleanRL style).

Covers: CartPole-v1 solved by train_static.py and by train_hebb.py (ABCD_lr), as scored by the
evaluate scripts; bit-identical results with one and two worker processes; the run folder (the
original's .dat and Fitness_values files, best/last, config.json, metrics.csv); a custom
``module:EnvId`` environment in worker processes; the original CarRacing-v0 command lines
unchanged apart from tiny budgets, and evaluation of the files they wrote; one-line errors with
exit code 2 and nothing written for bad input; the --render flag and --video.

Training and evaluation that a user would type run as real subprocesses, and so do the training
input errors (they stop before torch is imported, so they are cheap). The worker-count, evaluation
error and video checks call the scripts' ``main(argv)`` in this process instead: the same code,
minus an interpreter and torch start-up each, which would otherwise dominate the suite's time.

Budgets (CartPole, deterministic for a given seed): --popsize 64 --generations 20 --lr 0.05, seed 1
(static) and 3 (Hebbian). With these settings the last policy scores >= 475 over 10 evaluation
episodes for 7 of 8 seeds (static) and 6 of 8 (Hebbian; the others never leave a policy that
falls at once), so the seeds are typical, not lucky.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import evaluate_hebb
import evaluate_static
import train_hebb
import train_static
from es.files import METRICS_COLUMNS, load_dat, save_dat

ROOT = Path(__file__).resolve().parent.parent
ENV = {**os.environ, "SDL_VIDEODRIVER": "dummy", "MUJOCO_GL": "egl"}
CARTPOLE_STATIC_PARAMS = 4 * 128 + 128 * 64 + 64 * 2  # 8832, no biases
CARTPOLE_SYNAPSES = CARTPOLE_STATIC_PARAMS
PIXEL_SYNAPSES = 648 * 128 + 128 * 64 + 64 * 3  # 91328
CNN_SIZE = 6 * 3 * 3 * 3 + 8 * 6 * 5 * 5  # 1362


def run(script: str, *args, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, script, *map(str, args)], cwd=ROOT, env=ENV, capture_output=True,
                          text=True, timeout=timeout)


def run_in_process(main, *args) -> tuple[int, str, str]:
    """``script.main(argv)``: exit code, stdout, stderr."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(arg) for arg in args])
    return code, out.getvalue(), err.getvalue()


def succeeded(result: subprocess.CompletedProcess) -> subprocess.CompletedProcess:
    assert result.returncode == 0, f"exit {result.returncode}\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    return result


def only_run_dir(folder: Path) -> Path:
    runs = [path for path in folder.iterdir() if path.is_dir()]
    assert len(runs) == 1, runs
    return runs[0]


def episode_returns(stdout: str) -> list[float]:
    """The per-episode lines of the evaluate scripts: '<env> | episode i | seed s | return R | ...'."""
    return [float(value) for value in re.findall(r"\| return (-?\d+(?:\.\d+)?)", stdout)]


def train(tmp_path_factory, script: str, name: str, *args) -> tuple[subprocess.CompletedProcess, Path]:
    folder = tmp_path_factory.mktemp(name)
    result = succeeded(run(script, "--folder", folder, *args))
    return result, only_run_dir(folder)


# --- CartPole solved, and the run folder ---------------------------------------------------------


@pytest.fixture(scope="module")
def static_run(tmp_path_factory):
    return train(tmp_path_factory, "train_static.py", "static", "--environment", "CartPole-v1",
                 "--generations", 20, "--popsize", 64, "--lr", 0.05, "--seed", 1, "--threads", 2)


@pytest.fixture(scope="module")
def hebbian_run(tmp_path_factory):
    return train(tmp_path_factory, "train_hebb.py", "hebbian", "--environment", "CartPole-v1",
                 "--hebb_rule", "ABCD_lr", "--generations", 20, "--popsize", 64, "--lr", 0.05, "--seed", 3,
                 "--threads", 2)


def test_static_es_solves_cartpole(static_run):
    _, run_dir = static_run
    result = succeeded(run("evaluate_static.py", "--environment", "CartPole-v1",
                           "--path_weights", run_dir / "last.dat", "--episodes", 10))
    returns = episode_returns(result.stdout)
    assert len(returns) == 10 and np.mean(returns) >= 475, returns


def test_hebbian_es_solves_cartpole(hebbian_run):
    _, run_dir = hebbian_run
    result = succeeded(run("evaluate_hebb.py", "--environment", "CartPole-v1", "--hebb_rule", "ABCD_lr",
                           "--path_hebb", run_dir / "last_coeffs.dat", "--episodes", 10))
    returns = episode_returns(result.stdout)
    assert len(returns) == 10 and np.mean(returns) >= 475, returns


def read_metrics(run_dir: Path) -> list[dict]:
    with open(run_dir / "metrics.csv", newline="") as handle:
        reader = csv.DictReader(handle)
        assert tuple(reader.fieldnames) == METRICS_COLUMNS
        return list(reader)


def check_common_files(run_dir: Path, generations: int, seed: int, population: int) -> list[dict]:
    rows = read_metrics(run_dir)
    assert [int(row["generation"]) for row in rows] == list(range(1, generations + 1))
    fitness_files = list(run_dir.glob("Fitness_values_*_CartPole-v1.npy"))
    assert len(fitness_files) == 1
    np.testing.assert_allclose(np.load(fitness_files[0]), [float(row["fitness_mean"]) for row in rows])
    config = json.loads((run_dir / "config.json").read_text())
    assert (config["run"]["seed"], config["es"]["popsize"], config["run"]["generations"]) == (seed, population,
                                                                                             generations)
    assert config["env"]["env_ids"] == ["CartPole-v1"]
    assert config["wrappers"] == {"CartPole-v1": ["ArgmaxAction", "TimeLimit", "OrderEnforcing", "PassiveEnvChecker",
                                                  "CartPoleEnv"]}
    assert {"numpy", "gymnasium", "torch"} <= set(config["versions"])
    return rows


def test_static_run_folder_holds_the_original_files(static_run):
    _, run_dir = static_run
    rows = check_common_files(run_dir, 20, 1, 64)
    pattern = re.compile(r"CartPole-v1__rew_(-?\d+)__pop_64__(\d+)\.dat")
    saved = {int(match[2]): int(match[1]) for path in run_dir.glob("*.dat") if (match := pattern.fullmatch(path.name))}
    assert sorted(saved) == list(range(20))  # 0-based generation, as the original
    assert all(saved[g] == int(float(rows[g]["fitness_mean"])) for g in range(20))  # int(mean population fitness)
    last = load_dat(run_dir / "last.dat")
    assert last.shape == (CARTPOLE_STATIC_PARAMS,) and last.dtype == np.float32
    np.testing.assert_array_equal(last, load_dat(run_dir / f"CartPole-v1__rew_{saved[19]}__pop_64__19.dat"))
    assert load_dat(run_dir / "best.dat").shape == last.shape


def test_hebbian_run_folder_holds_the_original_files(hebbian_run):
    _, run_dir = hebbian_run
    rows = check_common_files(run_dir, 20, 3, 64)
    pattern = re.compile(r"HEBcoeffs__CartPole-v1__rew_(-?\d+)__ABCD_lr__init_uni__pop_64__coeffs__(\d+)\.dat")
    saved = {int(match[2]): int(match[1]) for path in run_dir.glob("*.dat") if (match := pattern.fullmatch(path.name))}
    assert sorted(saved) == list(range(20))
    assert all(saved[g] == int(float(rows[g]["fitness_mean"])) for g in range(20))
    coeffs = load_dat(run_dir / f"HEBcoeffs__CartPole-v1__rew_{saved[19]}__ABCD_lr__init_uni__pop_64__coeffs__19.dat")
    assert coeffs.shape == (CARTPOLE_SYNAPSES, 5)  # (n_syn, k): ABCD_lr has A, B, C, D and a learning rate
    np.testing.assert_array_equal(coeffs, load_dat(run_dir / "last_coeffs.dat"))
    assert load_dat(run_dir / "best_coeffs.dat").shape == coeffs.shape


# --- determinism across worker counts ------------------------------------------------------------


@pytest.fixture(scope="module")
def worker_count_runs(tmp_path_factory):
    """kind -> [(stdout, run folder) with --threads 1, the same with --threads 2]."""
    runs = {}
    for kind, main, extra in (("static", train_static.main, ()),
                              ("hebbian", train_hebb.main, ("--hebb_rule", "ABCD_lr"))):
        for threads in (1, 2):
            folder = tmp_path_factory.mktemp(f"{kind}_threads{threads}")
            code, out, err = run_in_process(main, "--environment", "CartPole-v1", "--generations", 3,
                                            "--popsize", 16, "--seed", 5, "--threads", threads, "--folder", folder,
                                            *extra)
            assert code == 0, out + err
            runs.setdefault(kind, []).append((out, only_run_dir(folder)))
    return runs


@pytest.mark.parametrize("kind", ["static", "hebbian"])
def test_same_seed_gives_bit_identical_results_with_one_and_two_workers(worker_count_runs, kind):
    outcomes = []
    for _, run_dir in worker_count_runs[kind]:
        last = next(run_dir.glob("last*.dat"))
        rows = [{key: row[key] for key in ("fitness_mean", "center_return", "env_steps")}
                for row in read_metrics(run_dir)]
        config = json.loads((run_dir / "config.json").read_text())
        outcomes.append((load_dat(last).tobytes(), rows, config["workers"]))
    assert outcomes[0][0] == outcomes[1][0]
    assert outcomes[0][1] == outcomes[1][1]
    assert (outcomes[0][2], outcomes[1][2]) == (1, 2)  # it really ran two worker processes


def test_custom_environment_trains_in_worker_processes(tmp_path):
    """Worker processes start fresh: they must import the ``module:`` of a custom environment too."""
    code, out, err = run_in_process(train_static.main, "--environment", "tests.custom_env_module:TestCorridor-v0",
                                    "--generations", 1, "--popsize", 4, "--seed", 0, "--threads", 2,
                                    "--folder", tmp_path)
    assert code == 0, out + err
    rows = read_metrics(only_run_dir(tmp_path))
    assert int(rows[0]["env_steps"]) == 5 * 20  # 4 members and the centre, 20 steps each


# --- the original CarRacing command lines --------------------------------------------------------


def test_original_static_car_racing_command_line_runs_and_evaluates(tmp_path):
    folder = tmp_path / "weights"
    result = succeeded(run("train_static.py", "--environment", "CarRacing-v0", "--generations", 1, "--popsize", 2,
                           "--print_every", 1, "--lr", 0.2, "--sigma", 0.1, "--decay", 0.995, "--threads", 1,
                           "--folder", folder, "--seed", 0))
    assert "CarRacing-v3" in result.stdout  # the retired id's notice
    weights = list(only_run_dir(folder).glob("CarRacing-v0__rew_*__pop_2__0.dat"))
    assert len(weights) == 1
    assert load_dat(weights[0]).shape == (CNN_SIZE + PIXEL_SYNAPSES,)
    evaluation = succeeded(run("evaluate_static.py", "--environment", "CarRacing-v0", "--path_weights", weights[0]))
    assert len(episode_returns(evaluation.stdout)) == 1


def test_original_hebbian_car_racing_command_line_runs_and_evaluates(tmp_path):
    folder = tmp_path / "heb_coeffs"
    succeeded(run("train_hebb.py", "--environment", "CarRacing-v0", "--hebb_rule", "ABCD_lr", "--popsize", 2,
                  "--lr", 0.2, "--decay", 0.995, "--sigma", 0.1, "--init_weights", "uni", "--print_every", 1,
                  "--generations", 1, "--threads", 1, "--folder", folder, "--distribution", "normal", "--seed", 0))
    run_dir = only_run_dir(folder)
    prefix = "HEBcoeffs__CarRacing-v0__rew_*__ABCD_lr__init_uni__pop_2"
    coeffs, = run_dir.glob(f"{prefix}__coeffs__0.dat")
    cnn, = run_dir.glob(f"{prefix}__CNN_parameters__0.dat")
    assert load_dat(coeffs).shape == (PIXEL_SYNAPSES, 5)
    assert load_dat(cnn).shape == (CNN_SIZE,)
    evaluation = succeeded(run("evaluate_hebb.py", "--environment", "CarRacing-v0", "--hebb_rule", "ABCD_lr",
                               "--path_hebb", coeffs, "--path_coev", cnn, "--init_weights", "uni"))
    assert len(episode_returns(evaluation.stdout)) == 1


# --- bad input -----------------------------------------------------------------------------------


def cartpole_weights(tmp_path: Path, size: int) -> Path:
    path = tmp_path / f"weights_{size}.dat"
    save_dat(path, np.zeros(size, dtype=np.float32))
    return path


BAD_TRAINING = [
    ("train_static.py", ["--environment", "CartPol-v1"], ["CartPol-v1", "CartPole-v1"]),
    ("train_static.py", ["--popsize", "1"], ["--popsize", "1"]),
    ("train_static.py", ["--popsize", "5"], ["--popsize 5 is odd", "mirrored pairs", "4 or 6"]),
    ("train_static.py", ["--sigma", "0"], ["--sigma", "0"]),
    ("train_static.py", ["--generations", "0"], ["--generations", "0"]),
    ("train_static.py", ["--decay", "0"], ["--decay", "(0, 1]"]),
    ("train_static.py", ["--decay", "1.5"], ["--decay", "(0, 1]"]),
    ("train_static.py", ["--seed", "-1"], ["--seed", "0 to 2147483647"]),
    ("train_static.py", ["--gen", "4"], ["--gen"]),
    ("train_static.py", ["--resume", ""], ["--resume", "empty"]),
    ("train_static.py", ["--popsize", "100000000"], ["--popsize 100000000", "GiB", "or less"]),
    ("train_static.py", ["--popsize", str(2**62)], ["--popsize", "or less"]),
    ("train_hebb.py", ["--hebb_rule", "X"], ["--hebb_rule", "ABCD_lr", "ABCD_lr_D_in_and_out", "'A'"]),
    ("train_hebb.py", ["--init_weights", "X"], ["--init_weights", "uni", "xa_uni", "coevolve"]),
    ("train_hebb.py", ["--distribution", "X"], ["--distribution", "normal", "uniform"]),
]


@pytest.mark.parametrize("script, args, named", BAD_TRAINING,
                         ids=[" ".join([script, *args]) for script, args, _ in BAD_TRAINING])
def test_bad_training_input_is_one_line_exit_2_and_writes_nothing(tmp_path, script, args, named):
    folder = tmp_path / "runs"
    defaults = {"--environment": "CartPole-v1", "--generations": "1", "--popsize": "4", "--threads": "1"}
    for flag, value in defaults.items():
        if flag not in args:
            args = [*args, flag, value]
    result = run(script, *args, "--folder", folder, timeout=60)
    assert result.returncode == 2, result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{script}: error:"), result.stderr
    for text in named:
        assert text in lines[0]
    assert not folder.exists()


def test_evaluate_missing_weight_file(tmp_path):
    missing = tmp_path / "nothing.dat"
    code, out, err = run_in_process(evaluate_static.main, "--environment", "CartPole-v1", "--path_weights", missing)
    assert code == 2 and err.count("\n") == 1 and err.startswith("evaluate_static.py: error:"), err
    assert str(missing) in err and "does not exist" in err
    assert list(tmp_path.iterdir()) == []


def test_evaluate_wrong_length_weight_file_names_both_lengths(tmp_path):
    weights = cartpole_weights(tmp_path, 1000)
    code, out, err = run_in_process(evaluate_static.main, "--environment", "CartPole-v1", "--path_weights", weights,
                                    "--video", tmp_path / "v.mp4")
    assert code == 2 and err.count("\n") == 1 and err.startswith("evaluate_static.py: error:"), err
    assert "1000" in err and str(CARTPOLE_STATIC_PARAMS) in err
    assert sorted(path.name for path in tmp_path.iterdir()) == [weights.name]  # no video started


def test_evaluate_hebbian_pixel_network_without_cnn_file(tmp_path):
    coeffs = tmp_path / "coeffs.dat"
    save_dat(coeffs, np.zeros((PIXEL_SYNAPSES, 5), dtype=np.float32))
    code, out, err = run_in_process(evaluate_hebb.main, "--environment", "CarRacing-v0", "--path_hebb", coeffs)
    assert code == 2 and err.count("\n") == 1 and err.startswith("evaluate_hebb.py: error:"), err
    assert "--path_coev" in err and str(CNN_SIZE) in err


# --- evaluate_static.py: --render and --video ----------------------------------------------------


@pytest.mark.parametrize("argv, expected", [
    ([], False),
    (["--render", "False"], False),
    (["--render", "0"], False),
    (["--render", "True"], True),  # the original's type=bool made every value True; ours parses it
    (["--render"], True),
])
def test_render_flag_parses_true_and_false(argv, expected):
    args = evaluate_static.build_parser().parse_args(["--path_weights", "w.dat", *argv])
    assert args.render is expected


def test_render_flag_refuses_other_values(capsys):
    with pytest.raises(SystemExit) as exited:
        evaluate_static.build_parser().parse_args(["--path_weights", "w.dat", "--render", "maybe"])
    assert exited.value.code == 2 and "maybe" in capsys.readouterr().err


def test_evaluate_with_render_false_writes_a_video(tmp_path, static_run):
    import imageio.v2 as imageio

    _, run_dir = static_run
    weights = next(run_dir.glob("CartPole-v1__rew_*__pop_64__0.dat"))  # an early, short-lived policy
    video = tmp_path / "cartpole.mp4"
    code, out, err = run_in_process(evaluate_static.main, "--environment", "CartPole-v1", "--path_weights", weights,
                                    "--render", "False", "--video", video)
    assert code == 0, out + err
    steps = int(re.search(r"\| steps (\d+)", out)[1])
    with imageio.get_reader(str(video)) as reader:
        frames = reader.count_frames()
        frame = reader.get_data(0)
    assert frames == steps + 1  # the reset frame and one per step
    assert frame.shape[2] == 3 and frame.shape[:2] in ((400, 600), (400, 608))


# --- experiment files (--config) --------------------------------------------------------------------


def test_an_experiment_file_configures_a_run_and_flags_given_too_override_it(tmp_path):
    experiment = tmp_path / "experiment.toml"
    experiment.write_text('[policy]\nkind = "static"\n\n[env]\nenvironment = "CartPole-v1"\n\n'
                          '[es]\npopsize = 6\nlr = 0.05\nsigma = 0.3\nfitness_l2 = 0.0\n\n'
                          '[run]\ngenerations = 1\nseed = 9\nthreads = 1\n')
    code, out, err = run_in_process(train_static.main, "--config", experiment, "--lr", "0.07",
                                    "--folder", tmp_path / "runs")
    assert code == 0, err
    config = json.loads((only_run_dir(tmp_path / "runs") / "config.json").read_text())
    assert (config["es"]["popsize"], config["es"]["lr"], config["es"]["sigma"], config["es"]["fitness_l2"]) == (
        6, 0.07, 0.3, 0.0)
    assert (config["run"]["seed"], config["run"]["generations"], config["env"]["env_ids"]) == (9, 1, ["CartPole-v1"])


@pytest.mark.parametrize("text, message", [
    ('[policy]\nkind = "hebbian"\n', "is a hebbian experiment; run it with train_hebb.py"),
    ('[es]\nlearning_rate = 0.1\n', "unknown settings es.learning_rate"),
    ('[es\n', "--config"),
])
def test_a_wrong_experiment_file_is_one_line_and_exit_2(tmp_path, text, message):
    experiment = tmp_path / "experiment.toml"
    experiment.write_text(text)
    code, out, err = run_in_process(train_static.main, "--config", experiment, "--folder", tmp_path / "runs")
    assert code == 2 and len(err.strip().splitlines()) == 1 and message in err, err
    assert not (tmp_path / "runs").exists()


def test_the_papers_experiment_files_hold_the_papers_settings():
    from cli.config import TrainConfig

    paths = sorted((ROOT / "experiments" / "paper").glob("*.toml"))
    assert paths, "experiments/paper holds no experiment files"  # a glob that matches nothing would check nothing
    for path in paths:
        config = TrainConfig.from_toml(path)
        assert (config.es.popsize, config.es.lr, config.es.decay, config.es.sigma) == (200, 0.2, 0.995, 0.1), path
        assert config.run.generations == 300 and config.run.threads == -1, path
        assert config.policy.kind == ("hebbian" if "hebbian" in path.stem else "static"), path
        if config.policy.kind == "hebbian":
            assert (config.policy.hebb_rule, config.policy.init_weights) == ("ABCD_lr", "uni"), path
