"""Evaluation statistics and adaptation plots (envs/evaluation.py, the evaluate scripts).

- the real evaluate_static.py prints one row per environment, mean ± std over N episodes, and
  ``--json`` holds the same numbers (CartPole pays 1 per step, so returns equal steps exactly);
- the distance walked by ants is the torso's straight-line (x, y) displacement from the start of
  the policy steps, and "forward" its x part, checked against MuJoCo's own ``info["x_position"]``
  and pyBullet's torso pose (and the progress reward, ~60.6 per metre along +x);
- ``trace_episode`` replays the first episode exactly and records per-step weight norms;
- the real evaluate_hebb.py ``--plot`` writes a PNG that matplotlib reads back, with no display;
- unwritable output paths are refused before any episode runs: one line, exit code 2.
"""

import csv
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from envs import ProblemSpec, rollout
from envs.evaluation import Trace, evaluate, format_table, trace_episode
from es.files import load_dat, save_dat
from policies import PolicySettings

ROOT = Path(__file__).resolve().parent.parent
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def run_script(script: str, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop("DISPLAY", None)  # headless, as on a cluster node
    return subprocess.run([sys.executable, str(ROOT / script), *args], capture_output=True, text=True,
                          cwd=ROOT, env=env, timeout=120)


def saved_params(tmp_path: Path, env_id: str, kind: str) -> Path:
    """A weight file as the training scripts write it, from the policy's generation-0 parameters."""
    problem = ProblemSpec((env_id,), PolicySettings(kind)).build()
    try:
        arrays = problem.policy.export(problem.policy.initial_params(np.random.default_rng(4)))
    finally:
        problem.close()
    (name, array), = arrays.items()
    path = tmp_path / f"{name}.dat"
    save_dat(path, array)
    return path


def test_static_table_and_json(tmp_path):
    weights = saved_params(tmp_path, "CartPole-v1", "static")
    out = tmp_path / "stats.json"
    result = run_script("evaluate_static.py", "--environment", "CartPole-v1,CartPole-v0", "--path_weights",
                        str(weights), "--episodes", "3", "--seed", "10", "--json", str(out))
    assert result.returncode == 0, result.stderr
    data = json.loads(out.read_text())
    assert data["kind"] == "static" and data["episodes"] == 3 and data["command"][0] == "evaluate_static.py"
    rows = {entry["environment"]: entry for entry in data["environments"]}
    assert list(rows) == ["CartPole-v1", "CartPole-v0"]
    lines = result.stdout.splitlines()
    header = next(index for index, line in enumerate(lines) if line.startswith("environment "))
    table = lines[header + 1:header + 3]
    for (env_id, entry), row in zip(rows.items(), table, strict=True):
        assert entry["seeds"] == [10, 11, 12]
        assert entry["returns"] == entry["steps"]  # +1 per step
        assert entry["mean"] == pytest.approx(np.mean(entry["returns"]))
        assert entry["std"] == pytest.approx(np.std(entry["returns"]))
        assert "distance_mean" not in entry
        assert row.split() == [env_id, "3", f"{entry['mean']:.2f}", "±", f"{entry['std']:.2f}", "-", "-"]
    assert f"statistics: {out}" in result.stdout


def test_the_centre_evaluations_seeds_can_be_evaluated(tmp_path):
    """Seeds from 2**31 on (the centre's evaluation, never a training episode) up to 2**32 - 1 are
    episode seeds, each the very episode ``rollout`` runs; one past the last is refused in one line."""
    weights = saved_params(tmp_path, "Pendulum-v1", "static")
    last = 2**32 - 1
    out = tmp_path / "stats.json"
    result = run_script("evaluate_static.py", "--environment", "Pendulum-v1", "--path_weights", str(weights),
                        "--episodes", "2", "--seed", str(last - 1), "--json", str(out))
    assert result.returncode == 0, result.stderr
    entry, = json.loads(out.read_text())["environments"]
    assert entry["seeds"] == [last - 1, last]
    problem = ProblemSpec(("Pendulum-v1",), PolicySettings("static")).build()
    try:
        params = problem.policy.load({"weights": load_dat(weights)})
        expected = [rollout(problem.envs[0], problem.policy, params, seed).total_return for seed in (last - 1, last)]
    finally:
        problem.close()
    assert entry["returns"] == expected
    refused = run_script("evaluate_static.py", "--environment", "Pendulum-v1", "--path_weights", str(weights),
                         "--episodes", "2", "--seed", str(last))
    assert refused.returncode == 2
    assert refused.stderr.strip().splitlines()[-1].endswith(f"runs past the largest episode seed {last}")
    assert "Traceback" not in refused.stderr


def test_mujoco_ant_distance_is_the_torso_displacement():
    problem = ProblemSpec(("Ant-v5",), PolicySettings("static")).build()
    try:
        params = problem.policy.initial_params(np.random.default_rng(4))
        (report,) = evaluate(problem, params, episodes=1, seed=3)
        env = problem.envs[0]
        env.reset(seed=3)
        start = env.unwrapped.data.qpos[:2].copy()
        last = {}
        episode = rollout(env, problem.policy, params, 3, observer=lambda t, r, s, info: last.update(info))
    finally:
        problem.close()
    end = np.array([last["x_position"], last["y_position"]])
    assert report.returns == [episode.total_return]
    assert report.distances == [pytest.approx(float(np.linalg.norm(end - start)), abs=1e-9)]
    assert report.forward == [pytest.approx(float(end[0] - start[0]), abs=1e-9)]
    row = format_table([report]).splitlines()[1].split()
    assert row[-6:] == [f"{report.distances[0]:.2f}", "±", "0.00", f"{report.forward[0]:.2f}", "±", "0.00"]


def test_pybullet_ant_distance_starts_after_the_burn_in():
    problem = ProblemSpec(("AntBulletEnv-v0",), PolicySettings("hebbian")).build()
    try:
        params = problem.policy.initial_params(np.random.default_rng(4))
        (report,) = evaluate(problem, params, episodes=1, seed=1)
        env = problem.envs[0]
        torso = env.unwrapped.robot.robot_body
        env.reset(seed=1)  # the burn-in runs inside the reset
        start = torso.current_position()[:2]
        rollout(env, problem.policy, params, 1)
        end = torso.current_position()[:2]
    finally:
        problem.close()
    assert report.distances == [pytest.approx(float(np.linalg.norm(end - start)), abs=1e-9)]
    assert report.forward == [pytest.approx(float(end[0] - start[0]), abs=1e-9)]
    # the return is pyBullet's progress reward: about 60.6 per metre toward the target at +x
    assert report.returns[0] / 60.6 == pytest.approx(report.forward[0], abs=0.02)


def test_trace_replays_the_first_episode_with_weight_norms():
    problem = ProblemSpec(("AntBulletEnv-v0",), PolicySettings("hebbian")).build()
    try:
        params = problem.policy.initial_params(np.random.default_rng(4))
        (report,) = evaluate(problem, params, episodes=1, seed=1)
        trace = trace_episode(problem, params, seed=1)
    finally:
        problem.close()
    assert trace.episode.total_return == report.returns[0]
    policy_steps = report.steps[0] - 40  # the burn-in is not a policy step
    assert len(trace.rewards) == len(trace.distances) == len(trace.forward) == len(trace.layer_norms) == policy_steps
    assert sum(trace.rewards) == pytest.approx(report.returns[0])
    assert trace.distances[-1] == pytest.approx(report.distances[0])
    assert trace.layer_shapes == [(128, 28), (64, 128), (8, 64)]
    assert np.all(np.array(trace.layer_norms) > 0)


def test_hebbian_plot_is_a_png(tmp_path):
    import matplotlib.image

    coeffs = saved_params(tmp_path, "AntBulletEnv-v0", "hebbian")
    plot = tmp_path / "adaptation.png"
    result = run_script("evaluate_hebb.py", "--environment", "AntBulletEnv-v0", "--path_hebb", str(coeffs),
                        "--seed", "1", "--plot", str(plot))
    assert result.returncode == 0, result.stderr
    assert plot.read_bytes()[:8] == PNG_SIGNATURE
    image = matplotlib.image.imread(plot)
    assert image.ndim == 3 and image.shape[0] > 200 and image.shape[1] > 200
    assert "adaptation plot (AntBulletEnv-v0, seed 1" in result.stdout


@pytest.mark.parametrize("flag", ["--json", "--plot"])
def test_unwritable_output_is_one_line_and_exit_2(tmp_path, capsys, flag):
    import evaluate_static

    weights = saved_params(tmp_path, "CartPole-v1", "static")
    missing = tmp_path / "no" / "such" / "file"
    code = evaluate_static.main(["--environment", "CartPole-v1", "--path_weights", str(weights),
                                 flag, str(missing)])
    error = capsys.readouterr().err.strip()
    assert code == 2
    assert error.splitlines() == [f"evaluate_static.py: error: {flag} {missing}: {missing.parent} is not an "
                                  "existing writable folder"]


@pytest.mark.parametrize("extra, message", [
    (["--json", "{folder}"],
     "--json {folder}: exists and is not a regular file (a folder or a device); give a file name"),
    (["--render", "--video", "{folder}/v.mp4"],
     "--video records frames off screen; it cannot be combined with --render"),
])
def test_impossible_outputs_are_one_line_and_exit_2(tmp_path, capsys, extra, message):
    import evaluate_static

    weights = saved_params(tmp_path, "CartPole-v1", "static")
    extra = [item.format(folder=tmp_path) for item in extra]
    code = evaluate_static.main(["--environment", "CartPole-v1", "--path_weights", str(weights), *extra])
    assert code == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        f"evaluate_static.py: error: {message.format(folder=tmp_path)}"]


def test_a_folder_of_runs_evaluates_its_newest_run(tmp_path):
    """``--path_weights FOLDER`` where FOLDER holds run folders (training's --folder): the newest run's last.dat,
    named in one line; the same numbers as that run folder given itself."""
    for seed in ("1", "2"):  # two runs in one folder, named by the time they started
        done = run_script("train_static.py", "--environment", "CartPole-v1", "--popsize", "4", "--generations", "1",
                          "--threads", "1", "--seed", seed, "--folder", str(tmp_path))
        assert done.returncode == 0, done.stderr
    runs = sorted(path for path in tmp_path.iterdir() if path.is_dir())
    assert len(runs) == 2
    by_folder = run_script("evaluate_static.py", "--path_weights", str(tmp_path), "--episodes", "2")
    by_run = run_script("evaluate_static.py", "--path_weights", str(runs[-1]), "--episodes", "2")
    assert by_folder.returncode == 0, by_folder.stderr
    assert f"run: {runs[-1]} (the newest of 2 in {tmp_path})" in by_folder.stdout
    assert by_folder.stdout.splitlines()[-1] == by_run.stdout.splitlines()[-1]


def trained_and_pruned(tmp_path: Path, generations: int) -> tuple[Path, Path]:
    """A small run folder as training leaves it, and beside it a copy that keeps what a campaign keeps while it
    trains: config.json, checkpoint.npz and metrics.csv."""
    done = run_script("train_static.py", "--environment", "CartPole-v1", "--popsize", "4", "--generations",
                      str(generations), "--threads", "1", "--seed", "1", "--folder", str(tmp_path / "runs"))
    assert done.returncode == 0, done.stderr
    (run,) = [path for path in (tmp_path / "runs").iterdir() if path.is_dir()]
    kept = tmp_path / "kept"
    kept.mkdir()
    for name in ("config.json", "checkpoint.npz", "metrics.csv"):
        shutil.copy(run / name, kept / name)
    return run, kept


def test_a_run_folder_keeping_only_its_checkpoint_evaluates_the_centres_saved_there(tmp_path):
    """A campaign keeps only config.json, checkpoint.npz and metrics.csv until training is complete, and never
    best*: ``--centre last`` (the default) and ``--centre best`` read the centre from the checkpoint, and give
    the numbers of the run's own last.dat and best.dat; the JSON says which centre, where it scored, and how."""
    run, kept = trained_and_pruned(tmp_path, generations=3)
    with open(run / "metrics.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    best_row = max(rows, key=lambda row: float(row["center_return"]))  # the first of the highest: best follows ">"
    for centre, file in (("last", "last.dat"), ("best", "best.dat")):
        by_file = run_script("evaluate_static.py", "--path_weights", str(run / file), "--episodes", "3",
                             "--json", str(tmp_path / f"{centre}_file.json"))
        by_checkpoint = run_script("evaluate_static.py", "--path_weights", str(kept), "--centre", centre,
                                   "--episodes", "3", "--json", str(tmp_path / f"{centre}.json"))
        assert by_file.returncode == 0 and by_checkpoint.returncode == 0, by_file.stderr + by_checkpoint.stderr
        from_file, from_checkpoint = (json.loads((tmp_path / f"{name}.json").read_text())
                                      for name in (f"{centre}_file", centre))
        assert from_checkpoint["environments"] == from_file["environments"]
        assert from_checkpoint["weights"] == from_file["weights"]  # the checkpoint beside best.dat says the same
        expected = ({"centre": "last", "generation": 3, "training_return": None} if centre == "last" else
                    {"centre": "best", "generation": int(best_row["generation"]),
                     "training_return": float(best_row["center_return"])})
        assert from_checkpoint["weights"] == expected
        line = ("the final centre (generation 3)" if centre == "last" else
                f"the best centre (training return {float(best_row['center_return']):.2f} at generation "
                f"{best_row['generation']})")
        assert f"weights: {line}, from {kept / 'checkpoint.npz'}" in by_checkpoint.stdout


def test_a_run_still_training_evaluates_its_centre_so_far_and_says_so(tmp_path):
    done = run_script("train_static.py", "--environment", "CartPole-v1", "--popsize", "4", "--generations", "2",
                      "--threads", "1", "--seed", "1", "--folder", str(tmp_path))
    assert done.returncode == 0, done.stderr
    (run,) = [path for path in tmp_path.iterdir() if path.is_dir()]
    config = json.loads((run / "config.json").read_text())
    config["run"]["generations"] = 300  # as a campaign's run at generation 2 of 300
    (run / "config.json").write_text(json.dumps(config))
    for path in run.iterdir():
        if path.name not in ("config.json", "checkpoint.npz", "metrics.csv"):
            path.unlink()
    result = run_script("evaluate_static.py", "--path_weights", str(run))
    assert result.returncode == 0, result.stderr
    assert (f"weights: the centre at generation 2 of 300: training is not complete, and a campaign keeps only its "
            f"checkpoint until it is, from {run / 'checkpoint.npz'}") in result.stdout


@pytest.mark.parametrize("args, message", [
    (("{run}/best.dat", "--centre", "best"), "--centre best picks a centre of a run folder, and {run}/best.dat is "
                                              "not a folder; give the run folder, or leave --centre out"),
    (("{kept}", "--path_reservoir", "{run}/best.dat"), "--path_reservoir: the centre comes from {kept}/checkpoint.npz, "
                                                        "which holds all of its weights; leave --path_reservoir out"),
    (("{kept}", "--centre", "worst"), None),
])
def test_a_centre_that_cannot_be_evaluated_is_one_line_and_exit_2(tmp_path, args, message):
    run, kept = trained_and_pruned(tmp_path, generations=1)
    path, *rest = (arg.format(run=run, kept=kept) for arg in args)
    refused = run_script("evaluate_static.py", "--path_weights", path, *rest)
    assert refused.returncode == 2 and "Traceback" not in refused.stderr
    last = refused.stderr.strip().splitlines()[-1]
    if message is None:  # argparse's own: the choices named
        assert "--centre: invalid choice: 'worst' (choose from" in last
    else:
        assert last == f"evaluate_static.py: error: {message.format(run=run, kept=kept)}"


def test_an_unreadable_checkpoint_is_named_in_one_line_and_exit_2(tmp_path):
    """A run folder that keeps only its checkpoint, and the checkpoint is damaged: the evaluation says which file,
    in its own words (not a resume's), and runs no episode."""
    _, kept = trained_and_pruned(tmp_path, generations=1)
    (kept / "checkpoint.npz").write_bytes(b"not a checkpoint")
    for centre in ("last", "best"):
        refused = run_script("evaluate_static.py", "--path_weights", str(kept), "--centre", centre)
        assert refused.returncode == 2 and "Traceback" not in refused.stderr
        assert refused.stderr.strip().splitlines() == [
            f"evaluate_static.py: error: cannot evaluate {kept}: {kept / 'checkpoint.npz'} is not a readable "
            "checkpoint; evaluate a weight file of the run instead"]


def test_the_adaptation_figure_keeps_a_long_environment_id_inside_it():
    from envs.rollout import Episode
    from report.adaptation import adaptation_figure

    steps = 960  # a damaged ant's full episode: 1000 steps, the first 40 burn-in
    trace = Trace("AntAsymRightBulletEnv-v0", 2**31, rewards=[1.0] * steps,
                  distances=list(np.linspace(0.0, 20.0, steps)), forward=list(np.linspace(0.0, 19.5, steps)),
                  layer_norms=[[10.0 + t, 20.0 + t, 5.0 + t] for t in range(steps)],
                  layer_shapes=[(128, 28), (64, 128), (8, 64)], episode=Episode(1124.75, 1000))
    figure = adaptation_figure(trace)
    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    width, height = figure.bbox.width, figure.bbox.height
    texts = [axes.title for axes in figure.axes] + [axes.xaxis.label for axes in figure.axes]
    shown = [text for text in texts if text.get_text()]
    assert any("AntAsymRightBulletEnv-v0, seed 2147483648" in text.get_text() for text in shown)
    assert any("return 1124.75, 1000 steps, the first 40 of them burn-in" in text.get_text() for text in shown)
    for text in shown:
        box = text.get_window_extent(renderer)
        assert box.x0 >= 0 and box.x1 <= width and box.y0 >= 0 and box.y1 <= height, (text.get_text(), box, width)
