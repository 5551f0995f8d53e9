"""Options beyond the 2020 algorithm: OpenAI's Adam and momentum, weight decay in the
gradient, observation normalisation, centre evaluation, an episode cap, the shapings, TensorBoard.

Exact values where the math is exact (one step of each optimiser written out by hand, the
shapings, RunningStat against plain numpy); every option deterministic with one and two workers
and across a resume (in-process ``train_static.main`` on CartPole, as tests/test_pinned.py); the
statistics saved beside the weights and picked up by evaluation; bad values refused in one line.
"""

from __future__ import annotations

import contextlib
import io
import math
import random
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import evaluate_static
import train_hebb
import train_static
from envs import ProblemSpec, make_env, rollout
from envs.wrappers import BurnIn, MaxEpisodeSteps
from es import files
from es.backends import Generation, Results, TaskBook
from es.loop import EVAL_SEEDS, SEED_LIMIT, Trainer
from es.observations import EPS, RunningStat, load_statistics, statistics_path
from es.optimizers import SGD, Adam, Momentum
from es.runfolder import RunFolder
from es.settings import ESSettings, RunSettings
from es.shaping import SHAPINGS
from es.worker import make_tasks
from policies import PolicySettings
from report import plots
from report.loggers.base import scalars
from tests.extras import need
from tests.run_helpers import assert_same_run, only_run

CARTPOLE = ("--environment", "CartPole-v1", "--popsize", "8", "--seed", "7")


def main(script, *argv) -> tuple[int, str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        try:
            code = script([str(arg) for arg in argv])
        except SystemExit as stop:  # argparse's errors
            code = stop.code
    return code, out.getvalue()


def train(folder: Path, *argv, script=train_static.main) -> Path:
    code, output = main(script, *argv, "--folder", folder)
    assert code == 0, output[-3000:]
    return only_run(folder)


# --- one step of each optimiser, by hand ---------------------------------------------------------

THETA = np.array([0.5, -1.0], dtype=np.float32)
WEIGHTED_SUM = np.array([2.0, -4.0])  # sum_m F_m eps_m
N, SIGMA = 4, 0.1


def test_one_sgd_step_with_weight_decay_by_hand():
    # g = ws / (N sigma) - C theta = [5, -10] - 0.1 [0.5, -1] = [4.95, -9.9]; theta += 0.2 g
    theta, state = SGD(l2coeff=0.1).step(THETA, WEIGHTED_SUM, N, SIGMA, 0.2, {})
    np.testing.assert_array_equal(theta, np.array([0.5 + 0.99, -1.0 - 1.98], dtype=np.float32))
    assert state == {}


def test_sgd_without_weight_decay_is_the_original_formula_bit_for_bit():
    theta = np.random.default_rng(0).normal(size=50).astype(np.float32)
    weighted = np.random.default_rng(1).normal(size=50)
    new, _ = SGD().step(theta, weighted, 200, 0.1, 0.2, {})
    assert new.tobytes() == (theta + (0.2 / (200 * 0.1)) * weighted).astype(np.float32).tobytes()


def test_one_momentum_step_by_hand():
    # OpenAI's gradient: g = ws / N - C theta = [0.5, -1] - 0.1 [0.5, -1] = [0.45, -0.9]
    # v = 0.9 [0.2, 0] + 0.1 g = [0.225, -0.09]; theta += 0.01 v
    theta, state = Momentum(momentum=0.9, l2coeff=0.1).step(THETA, WEIGHTED_SUM, N, SIGMA, 0.01,
                                                             {"velocity": np.array([0.2, 0.0])})
    np.testing.assert_allclose(state["velocity"], [0.225, -0.09], rtol=1e-15)
    np.testing.assert_array_equal(theta, np.array([0.50225, -1.0009], dtype=np.float32))


def test_two_adam_steps_by_hand():
    adam = Adam(beta1=0.9, beta2=0.999, l2coeff=0.1)
    # Step 1: g = [0.45, -0.9]; m = 0.1 g; v = 0.001 g^2; a = 0.01 sqrt(0.001) / 0.1
    # step = a m / (sqrt(v) + 1e-8) = 0.01 * |g| sqrt(0.001) / (|g| sqrt(0.001) + 1e-8) * sign(g)
    theta, state = adam.step(THETA, WEIGHTED_SUM, N, SIGMA, 0.01, {})
    root = math.sqrt(0.001)
    np.testing.assert_allclose(state["m"], [0.045, -0.09], rtol=1e-14)
    np.testing.assert_allclose(state["v"], [0.001 * 0.45 ** 2, 0.001 * 0.81], rtol=1e-14)
    assert int(state["t"]) == 1
    expected = [0.5 + 0.01 * 0.45 * root / (0.45 * root + 1e-8), -1.0 - 0.01 * 0.9 * root / (0.9 * root + 1e-8)]
    np.testing.assert_array_equal(theta, np.array(expected, dtype=np.float32))
    # Step 2, zero weighted sum: g = -0.1 theta_1 only; the bias corrections of t = 2
    second, state2 = adam.step(theta, np.zeros(2), N, SIGMA, 0.01, state)
    gradient = -0.1 * theta.astype(np.float64)
    m = 0.9 * state["m"] + 0.1 * gradient
    v = 0.999 * state["v"] + 0.001 * gradient ** 2
    size = 0.01 * math.sqrt(1 - 0.999 ** 2) / (1 - 0.9 ** 2)
    np.testing.assert_allclose(second, (theta + size * m / (np.sqrt(v) + 1e-8)).astype(np.float32), rtol=1e-7)
    assert int(state2["t"]) == 2


# --- shapings ------------------------------------------------------------------------------------


def test_rank_is_openai_centered_ranks_and_none_standardises_the_fitness():
    fitness = np.array([1.0, 4.0, 3.0, 2.0])
    np.testing.assert_allclose(SHAPINGS["rank"](fitness), [-0.5, 0.5, 1 / 6, -1 / 6], rtol=1e-15)
    np.testing.assert_allclose(SHAPINGS["none"](fitness), np.array([-1.5, 1.5, 0.5, -0.5]) / math.sqrt(1.25),
                               rtol=1e-15)
    # a non-finite fitness counts as the lowest finite one
    np.testing.assert_array_equal(SHAPINGS["none"](np.array([1.0, -np.inf, 3.0, 5.0])),
                                  SHAPINGS["none"](np.array([1.0, 1.0, 3.0, 5.0])))
    for name in SHAPINGS:
        assert SHAPINGS[name](np.full(4, 2.0)) is None, name
    assert SHAPINGS["none"](np.full(4, -np.inf)) is None


# --- RunningStat ---------------------------------------------------------------------------------


def episode_sums(observations: np.ndarray):
    return observations.sum(axis=0), np.square(observations).sum(axis=0), len(observations)


def test_running_stat_equals_plain_numpy_over_the_same_observations():
    rng = np.random.default_rng(0)
    episodes = [rng.normal(1.0, 3.0, size=(int(rng.integers(1, 400)), 5)) for _ in range(60)]
    everything = np.concatenate(episodes)
    stat = RunningStat.empty(5).merged(episode_sums(episode) for episode in episodes)
    count = len(everything) + EPS
    np.testing.assert_allclose(stat.sum, everything.sum(axis=0), rtol=1e-12)
    np.testing.assert_allclose(stat.mean, everything.sum(axis=0) / count, rtol=1e-12)
    variance = (np.square(everything).sum(axis=0) + EPS) / count - np.square(everything.sum(axis=0) / count)
    np.testing.assert_allclose(stat.std, np.sqrt(variance), rtol=1e-12)
    np.testing.assert_allclose(stat.mean, everything.mean(axis=0), rtol=1e-5)  # the EPS prior is tiny
    np.testing.assert_allclose(stat.std, everything.std(axis=0), rtol=1e-5)
    assert stat.observations == len(everything)


def test_running_stat_starts_as_the_identity_and_floors_the_std():
    empty = RunningStat.empty(3)
    np.testing.assert_array_equal(empty.mean, np.zeros(3))
    np.testing.assert_array_equal(empty.std, np.ones(3))
    constant = empty.merged([episode_sums(np.full((10, 3), 2.0))])
    np.testing.assert_allclose(constant.std, 0.1, rtol=1e-12)  # sqrt of es-starter's floor 1e-2


def test_sums_are_merged_in_task_order_whatever_order_they_arrive_in():
    rng = np.random.default_rng(1)
    tasks = make_tasks(np.arange(6), np.zeros(6), np.ones(6), np.arange(12).reshape(6, 2), 1,
                       np.ones((6, 2), dtype=bool))
    sums = [episode_sums(rng.normal(size=(int(rng.integers(1, 50)), 4)) * 10.0 ** rng.integers(-3, 4))
            for _ in tasks]
    merged = []
    for trial in range(5):
        book = TaskBook(tasks, ("CartPole-v1",), None)
        order = list(range(len(tasks)))
        random.Random(trial).shuffle(order)
        for index in order:
            book.record(index, "result", (1.0, 10, 0.0, sums[index]))
        merged.append(RunningStat.empty(4).merged(book.results.observations))
    for other in merged[1:]:
        assert other.sum.tobytes() == merged[0].sum.tobytes() and other.sumsq.tobytes() == merged[0].sumsq.tobytes()


# --- the episode cap -----------------------------------------------------------------------------


class _Counter(gym.Env):
    """Observation: the number of steps since reset; never ends by itself."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (1,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        self.t = 0
        return np.zeros(1, np.float32), {}

    def step(self, action):
        self.t += 1
        return np.full(1, self.t, np.float32), 0.0, False, False, {}


def policy_steps(env: gym.Env) -> tuple[int, bool, bool]:
    env.reset(seed=0)
    steps = 0
    while True:
        _, _, terminated, truncated, _ = env.step(np.zeros(1, np.float32))
        steps += 1
        if terminated or truncated:
            return steps, terminated, truncated


def test_the_cap_counts_policy_steps_and_the_environment_limit_counts_the_burn_in():
    # as the pyBullet ant: the registered limit (here 20) is inside the burn-in (here 5)
    def capped(cap):
        return MaxEpisodeSteps(BurnIn(gym.wrappers.TimeLimit(_Counter(), 20), 5), cap)

    assert policy_steps(capped(8)) == (8, False, True)  # the cap: 8 policy steps
    assert policy_steps(capped(100)) == (15, False, True)  # the environment's limit: 20 - 5
    with pytest.raises(ValueError, match="positive"):  # Gymnasium's own check
        MaxEpisodeSteps(_Counter(), 0)


def test_the_pybullet_ant_runs_its_burn_in_then_the_capped_policy_steps():
    env, _ = make_env("AntBulletEnv-v0", max_episode_steps=10)
    problem_policy = ProblemSpec(("AntBulletEnv-v0",)).build().policy
    episode = rollout(env, problem_policy, np.zeros(problem_policy.num_params, np.float32), 3)
    assert episode.steps == 10 + 40  # steps count the burn-in
    assert type(env).__name__ == "MaxEpisodeSteps"
    env.close()


# --- every option: deterministic with 1 and 2 workers and across a resume ------------------------

OPTIONS = {
    "adam": ("--optimizer", "adam", "--lr", "0.02", "--beta1", "0.8", "--beta2", "0.99"),
    "momentum": ("--optimizer", "momentum", "--lr", "0.05", "--momentum", "0.5"),
    "l2coeff": ("--l2coeff", "0.5"),
    "fitness_l2": ("--fitness_l2", "2000"),
    "shaping rank": ("--shaping", "rank"),
    "shaping none": ("--shaping", "none"),
    "obs_norm": ("--obs_norm", "--obs_norm_prob", "0.5", "--obs_clip", "2"),
    "eval_every": ("--eval_every", "2", "--eval_episodes", "3"),
    "max_episode_steps": ("--max_episode_steps", "20"),
    "all": ("--optimizer", "adam", "--lr", "0.02", "--l2coeff", "0.005", "--obs_norm", "--obs_norm_prob", "0.3",
            "--eval_every", "1", "--eval_episodes", "2", "--shaping", "rank", "--max_episode_steps", "60"),
}


@pytest.fixture(scope="module")
def default_run(tmp_path_factory):
    return train(tmp_path_factory.mktemp("default"), *CARTPOLE, "--generations", "3", "--threads", "1")


def files_of(run_dir: Path) -> dict[str, bytes]:
    return {path.name: path.read_bytes() for path in sorted(run_dir.glob("*.dat"))}


@pytest.mark.parametrize("option", list(OPTIONS))
def test_every_option_is_deterministic_with_two_workers_and_across_a_resume(option, tmp_path, default_run):
    argv = (*CARTPOLE, *OPTIONS[option])
    straight = train(tmp_path / "straight", *argv, "--generations", "3", "--threads", "1")
    split = train(tmp_path / "split", *argv, "--generations", "2", "--threads", "2")
    code, output = main(train_static.main, "--resume", split, "--generations", "3", "--threads", "2")
    assert code == 0, output
    assert_same_run(straight, split)
    for path in straight.glob("*.obs_norm.npz"):
        assert path.read_bytes() == (split / path.name).read_bytes(), path.name
    assert (files_of(straight)["last.dat"], files_of(straight)["best.dat"]) != (
        files_of(default_run)["last.dat"], files_of(default_run)["best.dat"])  # the option does something


def test_hebbian_with_observation_normalisation_and_adam_across_a_resume(tmp_path):
    argv = (*CARTPOLE, "--obs_norm", "--obs_norm_prob", "1", "--optimizer", "adam", "--lr", "0.05")
    straight = train(tmp_path / "straight", *argv, "--generations", "2", "--threads", "1", script=train_hebb.main)
    split = train(tmp_path / "split", *argv, "--generations", "1", "--threads", "2", script=train_hebb.main)
    assert main(train_hebb.main, "--resume", split, "--generations", "2")[0] == 0
    for name in ("last_coeffs.dat", "best_coeffs.dat", "last_coeffs.obs_norm.npz", "best_coeffs.obs_norm.npz"):
        assert (straight / name).read_bytes() == (split / name).read_bytes(), name


def test_ray_gives_the_serial_result_with_the_new_options(tmp_path):
    need("ray")
    argv = (*CARTPOLE, *OPTIONS["all"], "--generations", "2")
    serial = train(tmp_path / "serial", *argv, "--threads", "1")
    ray_run = train(tmp_path / "ray", *argv, "--threads", "2", "--backend", "ray")
    assert_same_run(serial, ray_run)
    assert (serial / "last.obs_norm.npz").read_bytes() == (ray_run / "last.obs_norm.npz").read_bytes()


# --- observation statistics: in the checkpoint, beside the weights, in evaluation -------------


@pytest.fixture(scope="module")
def normalised_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("normalised")
    return train(folder, *CARTPOLE, "--obs_norm", "--obs_norm_prob", "1", "--obs_clip", "3", "--generations", "2",
                 "--threads", "1", "--eval_every", "1", "--eval_episodes", "2")


def test_statistics_are_saved_beside_every_weight_file_and_in_the_checkpoint(normalised_run):
    weight_files = sorted(normalised_run.glob("*.dat"))
    assert len(weight_files) == 4  # two generations, last, best
    for weight_file in weight_files:
        saved = load_statistics(statistics_path(weight_file))
        assert saved.clip == 3.0 and saved.mean.shape == (4,) and saved.observations > 0
    with np.load(normalised_run / "checkpoint.npz") as checkpoint:
        last = load_statistics(normalised_run / "last.obs_norm.npz")
        stat = RunningStat(checkpoint["observations.sum"], checkpoint["observations.sumsq"],
                           float(checkpoint["observations.count"]))
        np.testing.assert_array_equal(stat.mean, last.mean)
        np.testing.assert_array_equal(stat.std, last.std)


def test_members_record_what_their_policy_acted_on_and_the_centre_never_does(tmp_path):
    spec = ProblemSpec(("CartPole-v1",), PolicySettings(obs_norm=True))
    trainer = Trainer.start(ESSettings(popsize=6, obs_norm_prob=1.0, eval_every=1, eval_episodes=2),
                            RunSettings(generations=1, threads=1), spec.build(), spec.build, spec.env_ids,
                            RunFolder(tmp_path), "CartPole-v1", log=lambda line: None)
    seen = []
    evaluate = trainer.evaluator.evaluate
    def recording(generation, progress=None):
        seen.append(evaluate(generation, progress))
        return seen[-1]

    trainer.evaluator.evaluate = recording
    try:
        trainer.generation()
    finally:
        trainer.close()
    (results,) = seen
    recorded = [sums for sums in results.observations if sums is not None]
    assert len(recorded) == 6 and all(sums is None for sums in results.observations[6:])  # centre, evaluation
    assert [count for _, _, count in recorded] == results.steps[:6].tolist()  # CartPole: steps = policy steps
    np.testing.assert_array_equal(trainer.observations.sum, sum(total for total, _, _ in recorded))
    assert trainer.observations.observations == results.steps[:6].sum()


def test_evaluation_picks_up_the_statistics_and_says_so(normalised_run):
    code, output = main(evaluate_static.main, "--environment", "CartPole-v1", "--path_weights",
                        normalised_run / "last.dat", "--episodes", "2")
    assert code == 0, output
    assert f"observation normalisation: statistics from {normalised_run / 'last.obs_norm.npz'}" in output
    # the same episodes as the training's own policy with those statistics
    saved = load_statistics(normalised_run / "last.obs_norm.npz")
    problem = ProblemSpec(("CartPole-v1",), PolicySettings(obs_norm=True, obs_clip=3.0)).build()
    problem.policy.observe((saved.mean, saved.std))
    params = files.load_dat(normalised_run / "last.dat")
    expected = [problem.evaluate(params, 0, seed).total_return for seed in (0, 1)]
    assert f"return {expected[0]:.2f}" in output and f"return {expected[1]:.2f}" in output


def test_missing_statistics_are_refused_in_one_line(normalised_run, tmp_path):
    run_copy = tmp_path / "run"
    run_copy.mkdir()
    for name in ("config.json", "last.dat"):
        (run_copy / name).write_bytes((normalised_run / name).read_bytes())
    code, output = main(evaluate_static.main, "--environment", "CartPole-v1", "--path_weights", run_copy / "last.dat")
    assert code == 2
    assert output.strip() == (f"evaluate_static.py: error: {run_copy / 'last.dat'} was trained with --obs_norm, "
                              f"but its observation statistics {run_copy / 'last.obs_norm.npz'} are missing; "
                              "put that file of the run beside it")


def test_pixels_are_not_normalised_and_the_run_says_so(tmp_path):
    code, output = main(train_static.main, "--environment", "CarRacing-v3", "--popsize", "2", "--generations", "1",
                        "--seed", "31", "--threads", "1", "--obs_norm", "--folder", tmp_path)
    assert code == 0, output
    assert "note: --obs_norm does nothing for pixel observations" in output
    run_dir = only_run(tmp_path)
    assert not list(run_dir.glob("*.npz")) or [path.name for path in run_dir.glob("*.npz")] == ["checkpoint.npz"]
    from tests.test_pinned import PINNED, parameters_hash

    assert parameters_hash(run_dir) == PINNED["static pixels"]  # exactly the run without --obs_norm


# --- centre evaluation ---------------------------------------------------------------------------


def test_centre_evaluation_columns_rank_and_best(normalised_run):
    rows = files.read_metrics(normalised_run / "metrics.csv")
    assert len(rows) == 2
    for row in rows:
        assert 1 <= int(row["center_rank"]) <= 9
        assert math.isfinite(float(row["center_eval_mean"])) and float(row["center_eval_std"]) >= 0
    means = [float(row["center_eval_mean"]) for row in rows]
    with np.load(normalised_run / "checkpoint.npz") as checkpoint:
        assert float(checkpoint["best_center"]) == max(means)
    # Row g evaluates the centre before generation g's step: row 1 theta_0 with no statistics yet,
    # row 2 the weights (and statistics) saved after generation 1 (file suffix __0).
    best = files.load_dat(normalised_run / "best.dat")
    best_statistics = load_statistics(normalised_run / "best.obs_norm.npz")
    (after_first,) = normalised_run.glob("CartPole-v1__*__0.dat")
    if means[1] > means[0]:
        np.testing.assert_array_equal(best, files.load_dat(after_first))
        np.testing.assert_array_equal(best_statistics.mean, load_statistics(statistics_path(after_first)).mean)
    else:
        assert not np.array_equal(best, files.load_dat(after_first))
        np.testing.assert_array_equal(best_statistics.mean, np.zeros(4))


def test_evaluation_seeds_are_never_training_seeds():
    assert EVAL_SEEDS[0] >= SEED_LIMIT
    settings = ESSettings(eval_every=3)
    assert [g for g in range(10) if settings.evaluates_centre(g)] == [2, 5, 8]
    assert not any(ESSettings().evaluates_centre(g) for g in range(10))


def test_the_plot_draws_the_evaluation_mean_and_reads_old_metrics(normalised_run, tmp_path):
    rows = files.read_metrics(normalised_run / "metrics.csv")
    data = plots.curves(rows)
    np.testing.assert_array_equal(data["eval_mean"], [float(row["center_eval_mean"]) for row in rows])
    old = [{key: value for key, value in row.items() if not key.startswith("center_eval")} for row in rows]
    assert np.isnan(plots.curves(old)["eval_mean"]).all()
    plots.save_run_plot(tmp_path / "fitness.png", rows, "test")
    assert (tmp_path / "fitness.png").stat().st_size > 0


def test_a_run_from_before_these_options_resumes(tmp_path):
    """Old metrics.csv (no new columns) and an old checkpoint (no dict fields) still resume."""
    run_dir = train(tmp_path, *CARTPOLE, "--generations", "1", "--threads", "1")
    old_columns = files.METRICS_COLUMNS[:16]
    rows = files.read_metrics(run_dir / "metrics.csv")
    text = ",".join(old_columns) + "\n" + "".join(",".join(row[key] for key in old_columns) + "\n" for row in rows)
    (run_dir / "metrics.csv").write_text(text)
    code, output = main(train_static.main, "--resume", run_dir, "--generations", "2")
    assert code == 0, output
    first, second = files.read_metrics(run_dir / "metrics.csv")
    assert first["center_rank"] == "" and second["center_rank"] != ""


# --- TensorBoard ---------------------------------------------------------------------------------


def test_tensorboard_holds_every_metrics_column(tmp_path):
    need("tensorboard")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    run_dir = train(tmp_path, *CARTPOLE, "--generations", "2", "--threads", "1", "--tensorboard",
                    "--eval_every", "2", "--eval_episodes", "2")
    events = EventAccumulator(str(run_dir / "tensorboard"))
    events.Reload()
    rows = files.read_metrics(run_dir / "metrics.csv")
    for name in files.METRICS_COLUMNS[1:]:
        points = {event.step: event.value for event in events.Scalars(name)}
        expected = {int(row["generation"]): float(row[name]) for row in rows if math.isfinite(float(row[name]))}
        assert points.keys() == expected.keys(), name
        for step, value in expected.items():
            assert points[step] == pytest.approx(value, rel=1e-6), name
    assert scalars({"center_rank": "", "center_eval_mean": "nan", "lr": "0.5"}) == {"lr": 0.5}


# --- bad input -------------------------------------------------------------------------------------


@pytest.mark.parametrize("flags, message", [
    (("--optimizer", "adam", "--beta1", "1"), "--beta1 must be in [0, 1), got 1.0"),
    (("--optimizer", "adam", "--beta2", "-0.1"), "--beta2 must be in [0, 1), got -0.1"),
    (("--optimizer", "momentum", "--momentum", "1.5"), "--momentum must be in [0, 1), got 1.5"),
    (("--l2coeff", "-0.01"), "--l2coeff must be a number >= 0, got -0.01"),
    (("--fitness_l2", "-1"), "--fitness_l2 must be in [0, 3.40282e+38], got -1.0"),
    (("--obs_norm", "--obs_norm_prob", "0"), "--obs_norm_prob must be in (0, 1], got 0.0"),
    (("--obs_norm", "--obs_norm_prob", "1.5"), "--obs_norm_prob must be in (0, 1], got 1.5"),
    (("--obs_norm", "--obs_clip", "0"), "--obs_clip must be a number > 0, got 0.0"),
    (("--eval_every", "2", "--eval_episodes", "0"), "--eval_episodes must be a whole number >= 1, got 0"),
    (("--eval_every", "0"), "--eval_every must be a whole number >= 1, got 0"),
    (("--max_episode_steps", "0"), "--max_episode_steps must be a whole number >= 1, got 0"),
    (("--beta1", "0.5"), "--beta1 has an effect only with --strategy openai --optimizer adam; add --optimizer adam or "
                         "leave --beta1 out"),
    (("--obs_clip", "5"), "--obs_clip has an effect only with --obs_norm; add --obs_norm or leave --obs_clip out"),
    (("--eval_episodes", "5"), "--eval_episodes has an effect only with --eval_every; add --eval_every or leave "
                               "--eval_episodes out"),
    (("--optimizer", "rmsprop"), "argument --optimizer: invalid choice: 'rmsprop'"),
])
def test_bad_values_are_one_line_and_create_nothing(flags, message, tmp_path):
    code, output = main(train_static.main, *CARTPOLE, *flags, "--generations", "1", "--folder", tmp_path / "runs")
    assert code == 2 and len(output.strip().splitlines()) == 1, output
    assert message in output
    assert not (tmp_path / "runs").exists()


def test_bad_values_in_an_experiment_file_are_refused_too(tmp_path):
    experiment = tmp_path / "bad.toml"
    experiment.write_text('[es]\noptimizer = "adam"\nbeta2 = 1.0\n')
    code, output = main(train_static.main, *CARTPOLE, "--config", experiment, "--generations", "1",
                        "--folder", tmp_path / "runs")
    assert code == 2 and output.strip().endswith("--beta2 must be in [0, 1), got 1.0")
    assert not (tmp_path / "runs").exists()


def test_generation_carries_the_published_statistics():
    statistics = (np.zeros(4), np.ones(4))
    generation = Generation(0, np.zeros(3, np.float32), 0.1, make_tasks(np.arange(2), np.zeros(2), np.ones(2),
                                                                          np.zeros((2, 1)), 1), statistics)
    assert generation.statistics is statistics
    assert Results.empty(3).observations == [None, None, None]
