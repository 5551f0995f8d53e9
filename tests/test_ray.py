"""The Ray backend (--backend ray): same theta as the process pool and one process, and faults.

One local Ray (2 CPUs, no dashboard) serves the whole module; the training scripts run in this
process so they join it instead of starting their own. Skipped where Ray is not installed (it is
optional), except the check that ``--backend ray`` then says how to install it.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

import train_static
from envs import ProblemSpec
from es.backends import EvaluationError, Generation, SerialEvaluator
from es.files import load_dat
from es.noise import NoiseTable
from es.worker import make_tasks
from tests.extras import need
from tests.ray_test_env import CrashingSpec

CARTPOLE = ("--environment", "CartPole-v1", "--popsize", "16", "--seed", "7")
ENV_IDS = ("CartPole-v1",)
POPULATION = 16
SIGMA = 0.1


@pytest.fixture(scope="module")
def ray_session():
    need("ray")
    import ray

    from es.backends.ray import start_ray

    started = start_ray(None, 2)
    yield ray
    if started:
        ray.shutdown()


def train(folder: Path, *argv: str) -> Path:
    """train_static.py with ``argv``; the folder of the one run it made."""
    assert train_static.main([*CARTPOLE, "--folder", str(folder), *argv]) == 0
    (run_dir,) = [path for path in folder.iterdir() if path.is_dir()]
    return run_dir


@pytest.fixture(scope="module")
def process_run(tmp_path_factory) -> Path:
    return train(tmp_path_factory.mktemp("process"), "--generations", "2", "--threads", "2")


# --- same results -------------------------------------------------------------------------------


def test_ray_backend_gives_the_process_pools_theta(ray_session, process_run, tmp_path):
    ray_run = train(tmp_path / "ray", "--generations", "2", "--threads", "2", "--backend", "ray")
    serial_run = train(tmp_path / "serial", "--generations", "2", "--threads", "1")
    expected = load_dat(process_run / "last.dat")
    assert np.array_equal(load_dat(ray_run / "last.dat"), expected)
    assert np.array_equal(load_dat(serial_run / "last.dat"), expected)
    config = json.loads((ray_run / "config.json").read_text())
    assert (config["run"]["backend"], config["run"]["ray_address"], config["workers"]) == ("ray", None, 2)


def test_run_started_on_ray_resumes_on_the_process_pool(ray_session, process_run, tmp_path):
    run_dir = train(tmp_path, "--generations", "1", "--threads", "2", "--backend", "ray")
    assert train_static.main(["--resume", str(run_dir), "--generations", "2", "--backend", "process"]) == 0
    assert np.array_equal(load_dat(run_dir / "last.dat"), load_dat(process_run / "last.dat"))


# --- faults -------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def generation():
    """A generation's tasks, its theta and noise, and the results of one process for it."""
    spec = ProblemSpec(ENV_IDS)
    problem = spec.build()
    dim = problem.policy.num_params
    noise = NoiseTable.create(0, 1 << 18)
    rng = np.random.default_rng(3)
    pairs = POPULATION // 2
    tasks = make_tasks(np.arange(POPULATION), np.repeat(noise.sample_indices(rng, dim, pairs), 2),
                       np.tile([1, -1], pairs), np.repeat(rng.integers(0, 2**31 - 1, (pairs, 1)), 2, axis=0),
                       len(ENV_IDS))
    theta = problem.policy.initial_params(np.random.default_rng(4))
    serial = SerialEvaluator(lambda: problem, noise, dim, ENV_IDS)
    work = Generation(0, theta, SIGMA, tasks)
    expected = serial.evaluate(work)
    serial.close()
    return dict(work=work, tasks=tasks, noise=noise, dim=dim, expected=expected)


def ray_evaluator(build_problem, generation):
    from es.backends.ray import RayEvaluator

    return RayEvaluator(build_problem, generation["noise"], generation["dim"], ENV_IDS, workers=2)


def assert_expected_results(results, generation) -> None:
    assert np.array_equal(results.returns, generation["expected"].returns)
    assert np.array_equal(results.steps, generation["expected"].steps)
    assert np.array_equal(results.penalties, generation["expected"].penalties)


def test_killed_actors_are_replaced_and_their_tasks_rerun(ray_session, generation, tmp_path):
    """Both actors are killed mid-generation, as a node going down would. Also: one episode raises,
    and is retried (the last pair's, dispatched after the kill).

    The actor that just reported is still taken for alive: its next task fails alone and is charged
    once; its retry must not go to the other dead actor (charged twice, the run would stop: 1 run in
    13 did, before the evaluator checked that an actor is alive before it hands it such a task).
    """
    seed = int(generation["tasks"][-1]["seed"])
    evaluator = ray_evaluator(CrashingSpec(seed, "raise", str(tmp_path / "raised")).build, generation)
    first_actors = list(evaluator._actors)
    done = []

    def kill_all_after_three(episodes: int, steps: int) -> None:
        done.append(episodes)
        if len(done) == 3:  # mid-generation: one actor is busy, the other just reported
            for actor in first_actors:
                ray_session.kill(actor)
            for actor in first_actors:  # ray.kill returns before the actor is dead: no task may reach it after
                while True:
                    try:
                        ray_session.get(actor.ready.remote(), timeout=30)
                    except ray_session.exceptions.RayActorError:
                        break
                    except ray_session.exceptions.GetTimeoutError:
                        continue

    try:
        results = evaluator.evaluate(generation["work"], kill_all_after_three)
        assert_expected_results(results, generation)
        assert (tmp_path / "raised").exists()
        assert any("a Ray worker died" in line or "Ray worker died" in line for line in results.warnings)
        replacements = [*evaluator._actors, *evaluator._starting.values()]  # one may still be starting
        assert len(replacements) == 2 and not set(replacements) & set(first_actors)
        assert_expected_results(evaluator.evaluate(generation["work"]), generation)
        assert set([*evaluator._actors, *evaluator._starting.values()]) == set(replacements)  # no one else died
    finally:
        evaluator.close()


def test_worker_that_exits_is_replaced_and_its_task_rerun(ray_session, generation, tmp_path):
    seed = int(generation["tasks"][5]["seed"])
    spec = CrashingSpec(seed, "exit", marker=str(tmp_path / "failed"), driver_pid=os.getpid())
    evaluator = ray_evaluator(spec.build, generation)
    try:
        results = evaluator.evaluate(generation["work"])
    finally:
        evaluator.close()
    assert (tmp_path / "failed").exists()
    assert_expected_results(results, generation)


def test_task_that_kills_its_worker_twice_stops_the_evaluation(ray_session, generation):
    seed = int(generation["tasks"][5]["seed"])
    evaluator = ray_evaluator(CrashingSpec(seed, "exit", driver_pid=os.getpid()).build, generation)
    try:
        with pytest.raises(EvaluationError, match=r"CartPole-v1 failed twice for member [45] .*Ray worker died"):
            evaluator.evaluate(generation["work"])
    finally:
        evaluator.close()


# --- without Ray --------------------------------------------------------------------------------


def test_backend_ray_without_ray_says_how_to_install_it(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray now fails, as where it is not installed
    monkeypatch.delitem(sys.modules, "es.backends.ray", raising=False)
    code = train_static.main([*CARTPOLE, "--generations", "1", "--threads", "2", "--backend", "ray",
                              "--folder", str(tmp_path)])
    assert code == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "pip install -r requirements-ray.txt" in error
    assert not any(tmp_path.iterdir())


def test_ray_address_without_backend_ray_is_refused(tmp_path, capsys):
    code = train_static.main([*CARTPOLE, "--ray_address", "auto", "--folder", str(tmp_path)])
    assert code == 2
    assert "--ray_address has an effect only with --backend ray" in capsys.readouterr().err
