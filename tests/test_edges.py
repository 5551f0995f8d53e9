"""The edges a new user hits: printed hints that work as printed, outputs that never
replace inputs, resume that never drops a flag, non-finite numbers stopped where they appear, sizes
and seeds refused up front, headless MuJoCo without a GL library, broken pipes and Ctrl-C.

Whatever a user types runs as a real process here when the point is the process (hints pasted into
a shell, `| head`, Ctrl-C); the rest calls the scripts' ``main(argv)`` in this process.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import re
import shlex
import signal
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

import evaluate_static
import train_static
from es.files import load_dat, save_dat
from tests.run_helpers import only_run

ROOT = Path(__file__).resolve().parent.parent
CARTPOLE = ("--environment", "CartPole-v1", "--popsize", "8", "--seed", "4", "--threads", "1")
CARTPOLE_PARAMS = 4 * 128 + 128 * 64 + 64 * 2
FAILING = ("--environment", "tests.failing_env:FailingEnv-v0", "--popsize", "4", "--seed", "2", "--threads", "1")


def in_process(main, *args) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(arg) for arg in args])
        except SystemExit as exit_:  # argparse's refusals
            code = exit_.code
    return code, out.getvalue(), err.getvalue()


def one_error_line(code: int, err: str, *named: str) -> str:
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and ": error: " in lines[0], err
    for text in named:
        assert text in lines[0], lines[0]
    return lines[0]


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def weights(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("weights") / "w.dat"
    save_dat(path, np.random.default_rng(0).uniform(-0.1, 0.1, CARTPOLE_PARAMS))
    return path


# --- 1. printed hints work as printed ---------------------------------------------------------------


def bare_shell() -> dict:
    """A shell with no virtual environment on its PATH, as a new terminal would be."""
    return {"PATH": "/usr/bin:/bin", "HOME": os.environ.get("HOME", "/root"), "SDL_VIDEODRIVER": "dummy"}


def test_printed_hints_run_when_pasted_outside_the_venv_in_a_folder_with_a_space(tmp_path, monkeypatch):
    place = tmp_path / "my place"
    place.mkdir()
    env = {**os.environ, "FAILING_ENV_STEP": "3", "FAILING_ENV_HOW": "raise", "PYTHONPATH": str(ROOT)}
    failed = subprocess.run([sys.executable, str(ROOT / "train_static.py"), *FAILING, "--generations", "2",
                             "--folder", "my runs"], cwd=place, env=env, capture_output=True, text=True, timeout=120)
    assert failed.returncode == 1, failed.stderr
    resume = failed.stdout.strip().splitlines()[-1].split("resume with: ", 1)[1]
    pasted = subprocess.run(["/bin/sh", "-c", resume], cwd=place, env={**bare_shell(), "PYTHONPATH": str(ROOT)},
                            capture_output=True, text=True, timeout=120)  # the environment is repaired now
    assert pasted.returncode == 0, pasted.stderr
    evaluate = pasted.stdout.strip().splitlines()[-1].split("evaluate with: ", 1)[1]
    words = shlex.split(evaluate)
    assert f"{place / 'my runs'}/" in words[words.index("--path_weights") + 1]  # by its absolute path, one word
    evaluated = subprocess.run(["/bin/sh", "-c", evaluate], cwd=tmp_path, env={**bare_shell(), "PYTHONPATH": str(ROOT)},
                               capture_output=True, text=True, timeout=120)
    assert evaluated.returncode == 0, evaluated.stderr
    assert "FailingEnv-v0" in evaluated.stdout


# --- 2. an output never replaces an input -----------------------------------------------------------


@pytest.mark.parametrize("flag", ["--json", "--plot", "--video"])
def test_an_output_that_is_the_weight_file_is_refused_and_the_file_kept(tmp_path, weights, flag):
    copy = tmp_path / "w.dat"
    copy.write_bytes(weights.read_bytes())
    link = tmp_path / "link.mp4"
    link.symlink_to(copy)
    before = digest(copy)
    for target in (copy, link):  # the same path, and the same file through a link
        code, out, err = in_process(evaluate_static.main, "--environment", "CartPole-v1", "--path_weights", copy,
                                    flag, target)
        one_error_line(code, err, flag, "weight file", "another file name")
        assert out == "" and digest(copy) == before


def test_two_outputs_of_the_same_name_are_refused(tmp_path, weights):
    code, out, err = in_process(evaluate_static.main, "--environment", "CartPole-v1", "--path_weights", weights,
                                "--json", tmp_path / "a", "--plot", tmp_path / "a")
    one_error_line(code, err, "--json and --plot are the same file")


# --- 3, 4. resume: never an empty value, never a silently dropped flag ------------------------------


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("runs")
    code, out, err = in_process(train_static.main, *CARTPOLE, "--generations", "1", "--folder", folder)
    assert code == 0, err
    return only_run(folder)


def test_resume_with_an_empty_value_is_refused(tmp_path):
    code, out, err = in_process(train_static.main, "--resume", "", "--folder", tmp_path / "runs")
    one_error_line(code, err, "--resume", "empty")
    assert not (tmp_path / "runs").exists()


def test_resume_refuses_flags_that_would_change_the_run_and_names_them(finished_run):
    before = {path.name: digest(path) for path in finished_run.iterdir()}
    code, out, err = in_process(train_static.main, "--resume", finished_run, "--lr", "0.9", "--popsize", "8",
                                "--environment", "Pendulum-v1", "--generations", "2")
    line = one_error_line(code, err, "--lr 0.9 (the run has 0.2)", "--environment Pendulum-v1 (the run has "
                          "CartPole-v1)", "start a new run")
    assert "--popsize" not in line  # given, but the value the run already has
    assert {path.name: digest(path) for path in finished_run.iterdir()} == before


def test_flags_are_not_abbreviated(finished_run):
    code, out, err = in_process(train_static.main, "--resume", finished_run, "--gen", "4")
    one_error_line(code, err, "--gen")


# --- 5. non-finite numbers ---------------------------------------------------------------------------


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_weight_file_holding_nan_or_inf_is_refused_at_load(tmp_path, bad):
    values = np.zeros(CARTPOLE_PARAMS)
    values[[3, 7]] = bad
    save_dat(tmp_path / "bad.dat", values)
    code, out, err = in_process(evaluate_static.main, "--environment", "CartPole-v1", "--path_weights",
                                tmp_path / "bad.dat")
    one_error_line(code, err, "2 NaN or infinite values")


def test_a_non_finite_update_stops_the_run_keeping_the_last_finite_theta(tmp_path):
    code, out, err = in_process(train_static.main, *CARTPOLE, "--generations", "3", "--lr", "1e308",
                                "--folder", tmp_path)
    line = one_error_line(code, err, "error: generation 1: the update is not finite (lr 1e+308")
    assert line.endswith("the checkpoint holds generation 0; a resume would meet it again: start a new run with a "
                         "lower --lr or a larger --sigma")  # and no resume command
    assert not any(line.startswith(("done", "error", "stopped")) for line in out.strip().splitlines())
    run_dir = only_run(tmp_path)
    with np.load(run_dir / "checkpoint.npz") as saved:
        assert int(saved["generation"]) == 0 and np.isfinite(saved["theta"]).all()


def test_the_generation_line_prints_lr_in_g_format(tmp_path):
    code, out, err = in_process(train_static.main, *CARTPOLE, "--generations", "1", "--lr", "0.0011",
                                "--folder", tmp_path)
    assert re.search(r"\| lr: 0\.0010945 \|", out), out  # 0.0011 * 0.995, all of it (%.6f would print 0.001095)


# --- 6. sizes and seeds refused up front ------------------------------------------------------------


def test_evaluate_seed_out_of_range_is_one_line_naming_seed(weights):
    code, out, err = in_process(evaluate_static.main, "--environment", "CartPole-v1", "--path_weights", weights,
                                "--seed", "-1")
    one_error_line(code, err, "--seed")


def test_an_empty_folder_is_refused(tmp_path):
    code, out, err = in_process(train_static.main, *CARTPOLE, "--generations", "1", "--folder", "")
    one_error_line(code, err, "--folder", "empty")


def test_original_serial_thread_counts_still_run_with_a_notice(tmp_path):
    for threads in ("0", "-2"):
        code, out, err = in_process(train_static.main, "--environment", "CartPole-v1", "--popsize", "4",
                                    "--generations", "1", "--threads", threads, "--folder", tmp_path / threads)
        assert code == 0, err
        assert f"note: --threads {threads} runs everything in this process" in out
        assert "workers: 1 " in out


# --- 7. evaluation outputs: checked first, the video written as it comes ----------------------------


def test_a_bad_video_path_is_refused_before_any_episode(tmp_path, weights):
    code, out, err = in_process(evaluate_static.main, "--environment", "CartPole-v1", "--path_weights", weights,
                                "--episodes", "3", "--video", tmp_path / "clip.gif")
    one_error_line(code, err, "--video", ".mp4")
    assert out == "" and not (tmp_path / "clip.gif").exists()


def test_the_video_holds_every_frame_of_the_first_episode(tmp_path, weights):
    import imageio.v2 as imageio

    video = tmp_path / "clip.mp4"
    code, out, err = in_process(evaluate_static.main, "--environment", "CartPole-v1", "--path_weights", weights,
                                "--episodes", "2", "--video", video)
    assert code == 0, err
    steps = int(re.search(r"episode 1 \| seed 0 \| return [-\d.]+ \| steps (\d+)", out).group(1))
    assert imageio.mimread(video, memtest=False).__len__() == steps + 1  # the reset's frame, then one per step


def test_a_png_video_is_a_strip_of_every_hundredth_frame(tmp_path):
    """A CartPole episode of up to 240 steps (the reset's frame, then one per step): frames 0, 100, 200, ...
    at half size, side by side, the same pixels as the episode rendered again from the same seed."""
    import gymnasium as gym
    from PIL import Image

    from report.video import STRIP_EVERY, VideoRecorder

    def episode(env):  # a controller that keeps the pole up: the whole 240 steps
        observation, _ = env.reset(seed=4)
        rendered = [env.render()]
        for _ in range(240):
            observation, _, terminated, truncated, _ = env.step(int(observation[2] + 0.5 * observation[3] > 0))
            rendered.append(env.render())
            if terminated or truncated:
                break
        return rendered

    recorder = VideoRecorder(gym.make("CartPole-v1", render_mode="rgb_array", max_episode_steps=240),
                             tmp_path / "strip.png")
    rendered = episode(recorder)
    recorder.close()
    picture = np.asarray(Image.open(tmp_path / "strip.png"))
    kept = rendered[0::STRIP_EVERY]
    height, width = rendered[0].shape[0] // 2, rendered[0].shape[1] // 2
    assert len(kept) >= 2 and picture.shape == (height, len(kept) * width, 3)
    for index, frame in enumerate(kept):
        np.testing.assert_array_equal(picture[:, index * width:(index + 1) * width], frame[::2, ::2, :3])


def test_a_strip_renders_only_the_frames_it_keeps(tmp_path):
    """A pyBullet frame costs milliseconds: a strip renders frames 0, 100, 200 of a 240-step episode, no
    others, and the evaluation's return is the one without a strip."""
    import gymnasium as gym

    from report.video import STRIP_EVERY, VideoRecorder

    class Counted(gym.Wrapper):
        def __init__(self, env):
            super().__init__(env)
            self.renders = 0

        def render(self):
            self.renders += 1
            return self.env.render()

    def episode(env) -> float:
        observation, _ = env.reset(seed=4)
        total = 0.0
        for _ in range(240):
            observation, reward, terminated, truncated, _ = env.step(int(observation[2] + 0.5 * observation[3] > 0))
            total += reward
            if terminated or truncated:
                break
        return total

    counted = Counted(gym.make("CartPole-v1", render_mode="rgb_array", max_episode_steps=240))
    recorder = VideoRecorder(counted, tmp_path / "strip.png")
    assert episode(recorder) == episode(gym.make("CartPole-v1", max_episode_steps=240)) == 240
    recorder.close()
    assert recorder.frames_written == 241 and counted.renders == len(range(0, 241, STRIP_EVERY)) == 3


# --- 8. headless MuJoCo without a GL library ---------------------------------------------------------


def test_importing_envs_sets_no_mujoco_backend():
    environment = {key: value for key, value in os.environ.items() if key != "MUJOCO_GL"}
    found = subprocess.run([sys.executable, "-c", "import os, envs; print(os.environ.get('MUJOCO_GL'))"], cwd=ROOT,
                           env=environment, capture_output=True, text=True, timeout=60)
    assert found.stdout.strip() == "None", found.stderr


def test_a_gl_backend_that_cannot_load_is_one_line_naming_what_to_install(tmp_path):
    """OSMesa is not installed here: MUJOCO_GL=osmesa cannot even import MuJoCo."""
    from envs.headless import loads

    if loads(("libOSMesa.so.8", "libOSMesa.so.6", "libOSMesa.so")):
        pytest.skip("OSMesa is installed here, so MUJOCO_GL=osmesa does load")
    weights = tmp_path / "cheetah.dat"
    save_dat(weights, np.zeros(17 * 128 + 128 * 64 + 64 * 6))
    environment = {key: value for key, value in os.environ.items() if key != "PYOPENGL_PLATFORM"}
    environment["MUJOCO_GL"] = "osmesa"
    for script, args in (("evaluate_static.py", ["--path_weights", weights, "--video", tmp_path / "c.mp4"]),
                         ("train_static.py", ["--generations", "1", "--popsize", "2", "--folder", tmp_path / "runs"])):
        result = subprocess.run([sys.executable, script, "--environment", "HalfCheetah-v5", *map(str, args)],
                                cwd=ROOT, env=environment, capture_output=True, text=True, timeout=120)
        one_error_line(result.returncode, result.stderr, "MUJOCO_GL=osmesa", "libosmesa6", "unset MUJOCO_GL")
    assert not (tmp_path / "c.mp4").exists() and not (tmp_path / "runs").exists()


def test_the_rendering_backend_is_chosen_only_among_those_that_load(monkeypatch):
    from envs import headless

    environ = {}
    monkeypatch.setattr(headless, "loads", lambda names: "libOSMesa.so" in names)
    assert headless.choose_mujoco_gl(environ) == "osmesa" and environ == {"MUJOCO_GL": "osmesa"}
    environ = {}
    monkeypatch.setattr(headless, "loads", lambda names: False)
    assert headless.choose_mujoco_gl(environ) is None and environ == {}
    assert headless.choose_mujoco_gl({"MUJOCO_GL": "egl"}) == "egl"  # the user's choice stands


# --- 9. pipes, Ctrl-C, failing environments, unclear messages, plots ---------------------------------


def test_a_closed_pipe_does_not_stop_the_run(tmp_path):
    command = (f"{sys.executable} train_static.py --environment CartPole-v1 --popsize 8 --generations 6 "
               f"--threads 1 --folder {tmp_path} | head -1")
    result = subprocess.run(["/bin/bash", "-c", command], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.stdout.startswith("run folder: ") and result.stdout.count("\n") == 1
    assert "Traceback" not in result.stderr and "BrokenPipe" not in result.stderr
    rows = (only_run(tmp_path) / "metrics.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 6  # the header, and every generation


def test_ctrl_c_during_evaluation_prints_the_episodes_done(tmp_path):
    save_dat(tmp_path / "w.dat", np.zeros(4 * 128 + 128 * 64 + 64 * 2))
    process = subprocess.Popen([sys.executable, "evaluate_static.py",
                                "--environment", "tests.failing_env:FailingEnv-v0",
                                "--path_weights", str(tmp_path / "w.dat"), "--episodes", "1000"], cwd=ROOT,
                               env={**os.environ, "FAILING_ENV_STEP": "5", "FAILING_ENV_HOW": "hang",
                                    "FAILING_ENV_AFTER": "1",  # the first episode ends, the second hangs
                                    "FAILING_ENV_ONCE": str(tmp_path / "hung"), "PYTHONUNBUFFERED": "1"},
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out = ""
        while "episode 1 " not in out and process.poll() is None:
            out += process.stdout.readline()
        process.send_signal(signal.SIGINT)
        rest, err = process.communicate(timeout=60)
    finally:
        process.kill()
    assert process.returncode == 130, err
    assert "interrupted; the episodes done:" in rest and re.search(r"FailingEnv-v0\s+\d+\s+\d", rest), rest
    assert "Traceback" not in err


def test_an_environment_that_raises_during_evaluation_is_one_line(tmp_path, monkeypatch):
    monkeypatch.setenv("FAILING_ENV_STEP", "3")
    monkeypatch.setenv("FAILING_ENV_HOW", "raise")
    save_dat(tmp_path / "w.dat", np.zeros(4 * 128 + 128 * 64 + 64 * 2))
    code, out, err = in_process(evaluate_static.main, "--environment", "tests.failing_env:FailingEnv-v0",
                                "--path_weights", tmp_path / "w.dat")
    lines = err.strip().splitlines()
    assert code == 1 and len(lines) == 1, err
    assert "FailingEnv-v0 failed in the episode with seed 0: RuntimeError: FailingEnv: failure at step 3" in lines[0]


@pytest.mark.parametrize("make, named", [
    (lambda path: path.mkdir(), "is a folder"),
    (lambda path: path.write_text("hello\n"), "not a weight file"),
    (lambda path: path.write_bytes(b""), "is empty"),
    (lambda path: (save_dat(path, np.zeros(100)), path.write_bytes(path.read_bytes()[:300])), "truncated"),
])
def test_unreadable_weight_files_say_what_they_are(tmp_path, make, named):
    path = tmp_path / "w.dat"
    make(path)
    code, out, err = in_process(evaluate_static.main, "--environment", "CartPole-v1", "--path_weights", path)
    one_error_line(code, err, named)


def test_a_bfloat16_tensor_loads_as_float32(tmp_path):
    import torch

    torch.save(torch.tensor([1.5, -2.0, 0.25], dtype=torch.bfloat16), tmp_path / "b.dat")
    np.testing.assert_array_equal(load_dat(tmp_path / "b.dat"), np.array([1.5, -2.0, 0.25], dtype=np.float32))


def test_an_unknown_environment_names_a_shell_command_to_list_them():
    import envs

    listing = r"python -c 'import envs, gymnasium; gymnasium.pprint_registry\(\)'"
    with pytest.raises(envs.EnvironmentError_, match=listing):
        envs.resolve_env_id("qqqqqqqqqqqqqqqqqq-v9")


def test_paper_help_is_whole():
    result = subprocess.run([sys.executable, "experiments/paper.py", "--help"], cwd=ROOT, capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 0
    assert "evaluate over 100 episodes." in result.stdout and "--dry-run prints the commands instead." in result.stdout


def test_learning_curves_count_generations_in_whole_numbers():
    from report.plots import run_figure

    rows = [dict(generation=g, fitness_mean=g, fitness_max=g + 1, fitness_min=g - 1, center_return=g)
            for g in (1, 2, 3)]
    axes = run_figure(rows, "t").axes[0]
    axes.figure.canvas.draw()
    assert all(float(tick).is_integer() for tick in axes.get_xticks())


# --- 10. closer to the original ----------------------------------------------------------------------


def test_fitness_values_are_float32_and_dat_archives_are_named_after_their_file(finished_run):
    (fitness,) = finished_run.glob("Fitness_values_*.npy")
    assert np.load(fitness).dtype == np.float32
    for path in finished_run.glob("*.dat"):
        names = zipfile.ZipFile(path).namelist()
        assert f"{path.stem}/data.pkl" in names, (path.name, names)
    config = json.loads((finished_run / "config.json").read_text())
    assert config["run"]["threads"] == 1


# --- an experiment file or a config.json goes around the flags' checks: the settings check themselves --------


@pytest.mark.parametrize("toml, named", [
    ("[es]\nsigma = 0", "--sigma must be in (0, 3.40282e+38], got 0"),
    ("[es]\nlr = \"0.1\"", "--lr must be a number, got '0.1'"),
    ("[es]\ndecay = 2.0", "--decay must be in (0, 1], got 2.0"),
    ("[es]\nepisodes = 0", "--episodes must be a whole number >= 1, got 0"),
    ("[es]\nnoise_size = 100", "--noise_size 100 is smaller than the 8832 parameters"),
    ("[run]\nthreads = 0", "--threads must be -1 (all cores) or a whole number >= 1, got 0"),
    ("[run]\nprint_every = 0", "--print_every must be a whole number >= 1, got 0"),
    ("[policy]\nobs_norm = \"false\"", "--obs_norm must be true or false, got 'false'"),
    ("[env]\nenvironment = 5", "--environment must be a string, got 5"),
    ("policy = 3", "[policy] must be a table of settings"),
    ("[es]\nobs_norm_prob = 0.5", "--obs_norm_prob has an effect only with --obs_norm"),
])
def test_bad_experiment_file_values_are_one_line_and_create_nothing(tmp_path, toml, named):
    (tmp_path / "bad.toml").write_text(toml + "\n")
    flags = CARTPOLE[:-2]  # not --threads: the file's threads would not count
    code, out, err = in_process(train_static.main, *flags, "--generations", "1", "--config", tmp_path / "bad.toml",
                                "--folder", tmp_path / "runs")
    one_error_line(code, err, named)
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())


@pytest.mark.parametrize("edit, named", [
    (lambda config: [], "config.json is not a JSON object"),
    (lambda config: config | {"run": config["run"] | {"threads": 0}}, "--threads must be -1"),
    (lambda config: config | {"es": config["es"] | {"sigma": "x"}}, "sigma must be a number, got 'x'"),
])
def test_a_config_json_edited_by_hand_is_refused_on_resume(finished_run, tmp_path, edit, named):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    for path in finished_run.iterdir():
        if path.is_file():
            (run_dir / path.name).write_bytes(path.read_bytes())
    (run_dir / "config.json").write_text(json.dumps(edit(json.loads((run_dir / "config.json").read_text()))))
    before = {path.name: digest(path) for path in run_dir.iterdir()}
    code, out, err = in_process(train_static.main, "--resume", run_dir, "--generations", "2")
    one_error_line(code, err, named)
    assert {path.name: digest(path) for path in run_dir.iterdir()} == before


def test_render_without_a_display_is_refused_before_any_environment_is_made(tmp_path, weights):
    environ = {key: value for key, value in os.environ.items()
               if key not in ("DISPLAY", "WAYLAND_DISPLAY", "SDL_VIDEODRIVER")}
    result = subprocess.run([sys.executable, "evaluate_static.py", "--environment", "CartPole-v1", "--path_weights",
                             str(weights), "--render"], cwd=ROOT, env=environ, capture_output=True, text=True,
                            timeout=120)
    one_error_line(result.returncode, result.stderr, "--render shows a window, and there is no display")


def test_video_of_an_environment_that_renders_nothing_is_refused_before_the_episodes(tmp_path):
    save_dat(tmp_path / "w.dat", np.zeros(2 * 128 + 128 * 64 + 64 * 2))
    code, out, err = in_process(evaluate_static.main, "--environment", "tests.custom_env_module:TestCorridor-v0",
                                "--path_weights", tmp_path / "w.dat", "--video", tmp_path / "c.mp4")
    one_error_line(code, err, "TestCorridor-v0 cannot render 'rgb_array' frames (its render modes: none)")
    assert not (tmp_path / "c.mp4").exists() and "episode" not in out
