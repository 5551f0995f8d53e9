"""The comparison with EvoTorch (benchmarks/vs_evotorch.py, vs_evotorch_speed.py, peers/evotorch_train.py) against
the real EvoTorch and real environments, with tiny budgets: the same network and layout on both sides, seeded
EvoTorch runs, the judge's held-out seeds, what is counted, and both commands' records."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.extras import need, need_module_level

need_module_level("bench")

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

import vs_evotorch  # noqa: E402
import vs_evotorch_speed  # noqa: E402
from peers import evotorch_train  # noqa: E402
from peers.evotorch_train import EvoTorchSettings  # noqa: E402

from envs import ProblemSpec  # noqa: E402
from es.loop import Trainer  # noqa: E402
from es.runfolder import RunFolder  # noqa: E402
from es.settings import ESSettings, RunSettings  # noqa: E402


@pytest.mark.parametrize("environment", ["CartPole-v1", "HalfCheetah-v5"])
def test_evotorch_evolves_this_tools_network_in_this_tools_layout(environment):
    """A flat vector means the same network to both tools: EvoTorch's GymNE network made from it gives this
    tool's outputs, output for output (the judge runs EvoTorch's centres as this tool's parameters)."""
    import torch

    ours = ProblemSpec((environment,)).build()
    theirs = evotorch_train.problem(environment, obs_norm=False)
    rng = np.random.default_rng(0)
    params = rng.normal(0.0, 0.3, ours.policy.num_params).astype(np.float32)
    assert theirs.solution_length == params.size
    network = theirs.make_net(torch.from_numpy(params))
    for observation in rng.normal(0.0, 1.0, (5, ours.net.obs_shape[0])).astype(np.float32):
        output, _ = ours.policy.act(params, ours.policy.reset(params, rng), observation)
        with torch.no_grad():
            expected = network(torch.from_numpy(observation)).numpy()
        np.testing.assert_allclose(output, expected, rtol=1e-5, atol=1e-6)
    ours.close()


def evotorch_centre(seed: int) -> np.ndarray:
    evotorch_train.seed_everything(seed)
    problem = evotorch_train.problem("CartPole-v1", obs_norm=True)
    searcher = evotorch_train.searcher(problem, EvoTorchSettings("snes", 4, sigma=0.1, obs_norm=True))
    searcher.step()
    searcher.step()
    return searcher.status["center"].numpy().astype(np.float32), problem.interaction_count


def test_evotorch_runs_are_functions_of_their_seed():
    """torch, numpy, random and the environment's reset stream seeded: the same seed, the same run."""
    first, steps = evotorch_centre(1)
    again, steps_again = evotorch_centre(1)
    other, _ = evotorch_centre(2)
    np.testing.assert_array_equal(first, again)
    assert steps == steps_again
    assert not np.array_equal(first, other)


def test_matched_runs_start_from_this_tools_centre(tmp_path):
    judge = vs_evotorch.Judge("CartPole-v1", obs_norm=True, episodes=1, target=475.0)
    spec = ProblemSpec(("CartPole-v1",))
    trainer = Trainer.start(ESSettings(strategy="snes", popsize=4), RunSettings(generations=1, threads=1, seed=3),
                            spec.build(), spec.build, spec.env_ids, RunFolder(tmp_path), "CartPole-v1",
                            log=lambda line: None)
    try:
        np.testing.assert_array_equal(vs_evotorch.initial_centre(judge, 3), trainer.state.theta)
    finally:
        trainer.close()
        judge.close()


def test_the_judge_uses_held_out_seeds_the_same_for_both_tools():
    judge = vs_evotorch.Judge("CartPole-v1", obs_norm=False, episodes=10, target=475.0)
    seeds = [judge.first_seed(seed) for seed in range(1, 50)]
    judge.close()
    assert all(2**31 <= seed and seed + 10 <= 2**32 for seed in seeds)  # training seeds are below 2**31 - 1
    assert len(set(seeds)) == len(seeds)
    assert seeds[0] == vs_evotorch.Judge("CartPole-v1", obs_norm=True, episodes=10, target=475.0).first_seed(1)


def test_the_judge_normalises_with_the_statistics_given_or_none(tmp_path):
    """A normalising judge given no statistics (none gathered yet) runs the identity, whatever it ran before."""
    plain = vs_evotorch.Judge("CartPole-v1", obs_norm=False, episodes=3, target=0.0)
    normalised = vs_evotorch.Judge("CartPole-v1", obs_norm=True, episodes=3, target=0.0)
    params = plain.problem.policy.initial_params(np.random.default_rng(0))
    from envs.evaluation import evaluate

    normalised.solved(params, (np.full(4, 5.0), np.full(4, 0.1)), 1)  # statistics that change every action
    normalised.solved(params, None, 1)
    [expected] = evaluate(plain.problem, params, 3, plain.first_seed(1))
    [found] = evaluate(normalised.problem, params, 3, normalised.first_seed(1))
    assert found.returns == expected.returns
    plain.close()
    normalised.close()


def test_the_judge_runs_evotorchs_centre_as_evotorch_would():
    """EvoTorch's centre with its observation statistics, judged by this tool's evaluation, returns on each
    held-out seed what EvoTorch's own policy (its normalisation layer, argmax) returns from that seed."""
    import gymnasium as gym
    import torch

    evotorch_train.seed_everything(4)
    problem = evotorch_train.problem("CartPole-v1", obs_norm=True)
    searcher = evotorch_train.searcher(problem, EvoTorchSettings("snes", 8, sigma=0.2, obs_norm=True))
    for _ in range(3):
        searcher.step()
    centre = searcher.status["center"].numpy().astype(np.float32)
    stats = problem.get_observation_stats()
    judge = vs_evotorch.Judge("CartPole-v1", obs_norm=True, episodes=4, target=0.0)
    judge.solved(centre, (np.asarray(stats.mean, np.float64), np.asarray(stats.stdev, np.float64)), 1)
    from envs.evaluation import evaluate

    [report] = evaluate(judge.problem, centre, 4, judge.first_seed(1))
    policy, env = problem.to_policy(torch.from_numpy(centre)), gym.make("CartPole-v1")
    for seed, expected in zip(report.seeds, report.returns):
        observation, _ = env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            with torch.no_grad():
                action = int(np.argmax(policy(torch.as_tensor(observation, dtype=torch.float32)).numpy()))
            observation, reward, terminated, truncated, _ = env.step(action)
            total, done = total + reward, terminated or truncated
        assert total == expected, f"seed {seed}"
    assert len(set(report.returns)) > 1 or report.returns[0] > 9  # a centre that acts, not one that falls at once
    judge.close()


def test_this_tools_count_leaves_out_its_centres_episode(tmp_path):
    """Members' steps only: on CartPole a return is its steps, so the generation's steps less the centre's
    return are what is counted."""
    spec = ProblemSpec(("CartPole-v1",))
    trainer = Trainer.start(ESSettings(strategy="snes", popsize=6), RunSettings(generations=2, threads=1, seed=1),
                            spec.build(), spec.build, spec.env_ids, RunFolder(tmp_path), "CartPole-v1",
                            log=lambda line: None)
    trainer.evaluator = counter = vs_evotorch.MemberSteps(trainer.evaluator, 6)
    try:
        rows = [trainer.generation(), trainer.generation()]
    finally:
        trainer.close()
    assert counter.steps == sum(int(row["env_steps"]) - int(row["center_return"]) for row in rows)


def test_unsolved_runs_count_as_the_budget():
    assert vs_evotorch.censored([1200, None, 900], 5000) == [1200.0, 5000.0, 900.0]


def test_steps_to_solve_command_writes_its_tables(tmp_path, capsys):
    """Every row on a tiny budget: each run stops at the budget, counted as it; the record holds each seed's
    steps, the settings table (both tools, numbers) and the results table (IQM, intervals, P)."""
    need("stats")
    code = vs_evotorch.main(["--seeds", "2", "--budget", "300", "--reps", "50", "--test_episodes", "2",
                             "--results", str(tmp_path)])
    assert code == 0
    [path] = tmp_path.glob("vs_evotorch-CartPole-v1-*.json")
    record = json.loads(path.read_text())
    assert record["timed"] is False and record["loaded"] is False
    assert set(record["measures"]) == {f"{strategy}_{settings}_{tool}" for strategy in ("snes", "pgpe")
                                       for settings in vs_evotorch.SETTINGS for tool in ("this_tool", "evotorch")}
    for measure in record["measures"].values():
        assert measure["rounds"] == 2 and all(0 < value <= 300 or value == 300 for value in measure["values"])
    settings, results = record["notes"]["settings"], record["notes"]["results"]
    assert len(settings["rows"]) == 12 and len(results["rows"]) == 6
    matched_snes = [row for row in settings["rows"] if row[:2] == ["snes", "matched"]]
    assert [row[3] for row in matched_snes] == [64, 64] and matched_snes[0][4] == matched_snes[1][4]
    from_zeros = [row for row in settings["rows"] if row[1] == "matched_from_zeros"]
    assert {row[-1] for row in from_zeros} == {"zeros"}
    assert all(set(cell) >= {"value", "low", "high"} for row in results["rows"] for cell in (row[2], row[3], row[6]))


def test_speed_command_times_both_commands(tmp_path):
    code = vs_evotorch_speed.main(["--environment", "CartPole-v1", "--popsize", "4", "--generations", "2",
                                   "--rounds", "2", "--results", str(tmp_path)])
    assert code == 0
    [path] = tmp_path.glob("vs_evotorch_speed-CartPole-v1-1w-*.json")
    record = json.loads(path.read_text())
    assert record["timed"] is True
    assert set(record["measures"]) == {"command", "generation", "this_tool_command", "evotorch_command",
                                       "this_tool_generation", "evotorch_generation"}
    assert all(value > 0 for measure in record["measures"].values() for value in measure["values"])
    assert all(steps > 0 for tool in ("this tool", "EvoTorch") for steps in record["notes"]["steps"][tool])


def test_speed_command_refused_by_a_training_command_ends_in_its_one_line(tmp_path, capsys):
    """An environment the training scripts do not know: their one-line refusal, exit 2, no record."""
    with pytest.raises(SystemExit) as stop:
        vs_evotorch_speed.main(["--environment", "Nope-v0", "--popsize", "4", "--generations", "1", "--rounds", "1",
                                "--results", str(tmp_path)])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "unknown environment 'Nope-v0'" in err
    assert not list(tmp_path.iterdir())
