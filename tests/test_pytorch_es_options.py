"""pytorch-es's algorithm choices as options of the one ES: ``--shaping nes``,
``--useAdam``, ``--variable_ep_len`` and the centre's rank "k of N+1", with small CartPole budgets.
"""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np

import train_static
from envs import ProblemSpec, rollout
from es.files import load_dat, read_metrics
from es.shaping import SHAPINGS
from tests.run_helpers import assert_same_run, only_run, small_trainer

CARTPOLE = ("--environment", "CartPole-v1", "--popsize", "8", "--seed", "6", "--lr", "0.05")


def train(folder, *argv) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = train_static.main([*map(str, argv), "--folder", str(folder)] if "--resume" not in argv
                                 else list(map(str, argv)))
    return code, out.getvalue(), err.getvalue()


def test_nes_is_a_shaping_of_the_one_registry_and_moves_theta_its_own_way(tmp_path):
    assert SHAPINGS["nes"].__name__ == "nes_utilities"
    thetas = {}
    for shaping in ("rank_std", "nes"):
        for threads in ("1", "2"):
            code, out, err = train(tmp_path / f"{shaping}{threads}", *CARTPOLE, "--generations", "2",
                                   "--shaping", shaping, "--threads", threads)
            assert code == 0, err
            thetas[shaping, threads] = load_dat(only_run(tmp_path / f"{shaping}{threads}") / "last.dat").tobytes()
    assert thetas["nes", "1"] == thetas["nes", "2"]
    assert thetas["nes", "1"] != thetas["rank_std", "1"]


def test_use_adam_is_optimizer_adam(tmp_path):
    results = {}
    for flags in (("--useAdam",), ("--optimizer", "adam")):
        folder = tmp_path / flags[-1]
        code, out, err = train(folder, *CARTPOLE, "--generations", "2", "--threads", "1", *flags)
        assert code == 0, err
        run_dir = only_run(folder)
        assert json.loads((run_dir / "config.json").read_text())["es"]["optimizer"] == "adam"
        results[flags] = load_dat(run_dir / "last.dat").tobytes()
    assert len(set(results.values())) == 1
    code, out, err = train(tmp_path, "--resume", only_run(tmp_path / "adam"), "--useAdam", "--generations", "3")
    assert code == 0, err  # the run's own setting, given again
    code, out, err = train(tmp_path / "sgd", *CARTPOLE, "--generations", "1", "--threads", "1")
    code, out, err = train(tmp_path, "--resume", only_run(tmp_path / "sgd"), "--useAdam", "--generations", "2")
    assert code == 2 and "--optimizer adam (the run has sgd)" in err


class RecordingEvaluator:
    """Passes evaluations through, keeping each generation's tasks and results."""

    def __init__(self, evaluator):
        self.evaluator, self.seen = evaluator, []
        self.workers = evaluator.workers

    def evaluate(self, generation, progress=None):
        results = self.evaluator.evaluate(generation, progress)
        self.seen.append((generation.tasks.copy(), results.steps.copy()))
        return results

    def close(self):
        self.evaluator.close()


def test_variable_episode_length_caps_each_generation_at_twice_the_last_mean(tmp_path):
    from dataclasses import replace

    trainer = small_trainer(tmp_path, popsize=8, generations=4)
    trainer.es = replace(trainer.es, variable_ep_len=True)
    trainer.evaluator = RecordingEvaluator(trainer.evaluator)
    try:
        trainer.train()
    finally:
        trainer.close()
    caps = []
    for tasks, steps in trainer.evaluator.seen:
        cap = int(tasks["max_steps"][0])
        assert (tasks["max_steps"] == cap).all()
        if cap:
            assert steps.max() <= cap  # CartPole has no burn-in: env steps are policy steps
        caps.append((cap, int(2 * steps[:8].mean())))  # the members' tasks come first, the centre last
    assert caps[0][0] == 0  # the first generation is not capped
    assert [cap for cap, _ in caps[1:]] == [next_cap for _, next_cap in caps[:-1]]
    rows = read_metrics(tmp_path / "metrics.csv")
    assert [int(row["episode_cap"]) for row in rows] == [cap for cap, _ in caps]


def test_variable_episode_length_resumes_exactly(tmp_path):
    options = (*CARTPOLE, "--variable_ep_len", "--threads", "1")
    assert train(tmp_path / "straight", *options, "--generations", "4")[0] == 0
    assert train(tmp_path / "split", *options, "--generations", "2")[0] == 0
    split = only_run(tmp_path / "split")
    code, out, err = train(tmp_path, "--resume", split, "--generations", "4", "--threads", "2")
    assert code == 0, err
    assert "episodes capped at" in out
    assert_same_run(only_run(tmp_path / "straight"), split)


def test_the_rollout_stops_at_its_cap():
    problem = ProblemSpec(("CartPole-v1",)).build()
    try:
        params = problem.policy.initial_params(np.random.default_rng(0))
        uncapped = rollout(problem.envs[0], problem.policy, params, seed=3)
        capped = rollout(problem.envs[0], problem.policy, params, seed=3, max_steps=uncapped.steps - 2)
        assert capped.steps == uncapped.steps - 2 and capped.total_return == uncapped.total_return - 2
    finally:
        problem.close()


def test_the_generation_line_gives_the_centres_rank_among_n_plus_1(tmp_path):
    code, out, err = train(tmp_path, *CARTPOLE, "--generations", "1", "--threads", "1")
    rank = int(read_metrics(only_run(tmp_path) / "metrics.csv")[0]["center_rank"])
    assert f"(rank {rank} of 9)" in out
