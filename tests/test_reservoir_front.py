"""The reservoir front end (``--reservoir``, policies/reservoir.py): an evolved head reading ER-MRL's echo
state network instead of the observation.

Its state against the leaky-integrator equation, episode after episode; its per-member matrices against a
fresh build; the evolved hyperparameters' encoding; and real CartPole-v1 runs with tiny budgets, through
the scripts' ``main``: the same parameters with one or two workers and across a resume, evaluation of a
trained run, and the one-line refusals. Skipped where the optional extra is not installed.
"""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.extras import need_module_level

need_module_level("reservoirs")

from scipy import sparse  # noqa: E402

import evaluate_hebb  # noqa: E402
import evaluate_static  # noqa: E402
import train_hebb  # noqa: E402
import train_static  # noqa: E402
from cli.config import TrainConfig  # noqa: E402
from envs import ProblemSpec  # noqa: E402
from envs.evaluation import trace_episode  # noqa: E402
from es.files import load_dat, read_metrics, save_dat  # noqa: E402
from policies import NetworkSpec, PolicySettings, make_policy  # noqa: E402
from policies.normalised import NormalisedInputs  # noqa: E402
from policies.reservoir import BOUNDS, Hyperparameters, ReservoirFrontEnd, genes, hyperparameters  # noqa: E402
from reservoirs.esn import EchoStateNetwork, ReservoirSettings  # noqa: E402
from tests.run_helpers import only_run  # noqa: E402
from tests.test_modern_es import main as run  # noqa: E402  (a script's main: exit code and output)
from tests.test_pinned import parameters_hash  # noqa: E402
from tests.test_reservoirs import plain_loop  # noqa: E402

UNITS, INPUTS, SEED = 30, 6, 4
RESERVOIR = ("--environment", "CartPole-v1", "--popsize", "8", "--seed", "5", "--reservoir", "--reservoir_units",
             str(UNITS))
# case -> (training script, its flags beyond RESERVOIR)
RUNS = {"static, evolved reservoir": (train_static.main, ("--reservoir_evolve",)),
        "hebbian, given reservoir": (train_hebb.main, ("--reservoir_lr", "0.5", "--reservoir_sr", "0.9",
                                                       "--hebb_rule", "AD"))}


def train(folder: Path, script, *argv) -> tuple[Path, str]:
    code, output = run(script, *argv, "--folder", folder)
    assert code == 0, output[-3000:]
    return only_run(folder), output


def front_end(evolve: bool = False, kind: str = "static", **settings) -> ReservoirFrontEnd:
    return make_policy(PolicySettings(kind, reservoir=True, reservoir_units=UNITS, reservoir_seed=SEED,
                                      reservoir_evolve=evolve, **settings), NetworkSpec((INPUTS,), 2))


def rebuilt(values: Hyperparameters, units: int = UNITS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(W, W_in, b) of a reservoir built from scratch with these hyperparameters (reservoirs.esn)."""
    settings = ReservoirSettings(units, values.leak_rate, values.spectral_radius, values.input_scaling)
    return EchoStateNetwork(INPUTS, settings, SEED).matrices()


# --- the reservoir ---------------------------------------------------------------------------------


@pytest.mark.parametrize("evolve", [False, True])
def test_state_is_the_leaky_integrator_equation_from_zero_every_episode(evolve):
    policy = front_end(evolve, reservoir_lr=0.3, reservoir_sr=1.7, reservoir_iss=2.5)
    rng = np.random.default_rng(0)
    params = policy.initial_params(rng)
    if evolve:
        params[-3:] = (0.4, -1.2, 0.8)
    values = policy.hyperparameters(params)
    assert (values == Hyperparameters(0.3, 1.7, 2.5)) != evolve
    weights, input_weights, bias = rebuilt(values)
    for episode in rng.normal(size=(2, 25, INPUTS)).astype(np.float32):
        state = policy.reset(params, rng)
        np.testing.assert_array_equal(state.state, np.zeros(UNITS))
        states = []
        for observation in episode:
            _, state = policy.act(params, state, observation)
            states.append(state.state.copy())
            np.testing.assert_array_equal(state.features, state.state.astype(np.float32))  # what the head reads
        expected = plain_loop(weights, input_weights, bias, values.leak_rate, episode.astype(np.float64))
        np.testing.assert_allclose(np.array(states), expected, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("units", [2, 5, UNITS])
def test_each_members_rescaled_matrices_are_those_of_a_fresh_build_bit_for_bit(units):
    policy = make_policy(PolicySettings("static", reservoir=True, reservoir_units=units, reservoir_seed=SEED,
                                        reservoir_evolve=True), NetworkSpec((INPUTS,), 2))
    params = policy.initial_params(np.random.default_rng(0))
    for member_genes in ((0.0, 0.0, 0.0), (2.5, -3.0, 1.5), (-4.0, 6.0, -2.0)):
        params[-3:] = member_genes
        state = policy.reset(params, np.random.default_rng(0))
        weights, input_weights, bias = rebuilt(policy.hyperparameters(params), units)
        for data, matrix, expected in ((state.recurrent, policy.matrices.recurrent, weights),
                                       (state.inputs, policy.matrices.input_signs, input_weights)):
            scaled = sparse.csr_array((data, matrix.indices, matrix.indptr), shape=matrix.shape).toarray()
            np.testing.assert_array_equal(scaled, expected)
        np.testing.assert_array_equal(policy._bias, bias)


def test_with_obs_norm_the_reservoir_reads_the_normalised_observation():
    policy = make_policy(PolicySettings("static", reservoir=True, reservoir_units=UNITS, reservoir_seed=SEED,
                                        obs_norm=True, obs_clip=1.5), NetworkSpec((INPUTS,), 2))
    assert isinstance(policy, NormalisedInputs) and isinstance(policy.inner, ReservoirFrontEnd)
    mean, std = np.linspace(-1, 1, INPUTS), np.linspace(0.5, 2, INPUTS)
    policy.observe((mean, std))
    rng = np.random.default_rng(1)
    params, observations = policy.initial_params(rng), rng.normal(size=(10, INPUTS)).astype(np.float32)
    state, states = policy.reset(params, rng), []
    for observation in observations:
        _, state = policy.act(params, state, observation)
        states.append(state.state.copy())
    normalised = np.clip((observations - mean) / std, -1.5, 1.5).astype(np.float32).astype(np.float64)
    expected = plain_loop(*rebuilt(Hyperparameters(0.3, 1.0, 1.0)), 0.3, normalised)
    np.testing.assert_allclose(np.array(states), expected, rtol=1e-12, atol=1e-14)


def test_a_hebbian_heads_adaptation_trace_shows_its_own_layers():
    problem = ProblemSpec(("CartPole-v1",), PolicySettings("hebbian", reservoir=True, reservoir_units=UNITS,
                                                           reservoir_seed=1)).build()
    try:
        trace = trace_episode(problem, problem.policy.initial_params(np.random.default_rng(0)), seed=0)
    finally:
        problem.close()
    assert trace.layer_shapes == [(128, UNITS), (64, 128), (2, 64)]
    assert len(trace.layer_norms) == len(trace.rewards) > 0


# --- evolved hyperparameters -----------------------------------------------------------------------


def test_genes_map_into_er_mrls_bounds_monotonically_and_start_at_the_given_values():
    lows, highs = np.array([low for low, _ in BOUNDS.values()]), np.array([high for _, high in BOUNDS.values()])
    previous = lows
    for gene in (-3e38, -800.0, -40.0, -1.0, 0.0, 1.0, 40.0, 800.0, 3e38):
        values = np.array(list(vars(hyperparameters(np.full(3, gene))).values()))
        assert np.all(lows <= values) and np.all(values <= highs), gene
        assert np.all(values >= previous), gene
        previous = values
    middle = hyperparameters(np.zeros(3))  # the geometric middle: where ER-MRL's CMA-ES starts
    assert vars(middle) == pytest.approx({"leak_rate": 0.1, "spectral_radius": 0.1, "input_scaling": 1.0}, rel=1e-12)
    np.testing.assert_allclose(genes(Hyperparameters(0.1, 0.1, 1.0)), 0.0, atol=1e-7)
    assert vars(hyperparameters(genes(Hyperparameters(0.3, 1.7, 2.5)))) == pytest.approx(
        {"leak_rate": 0.3, "spectral_radius": 1.7, "input_scaling": 2.5}, rel=1e-6)  # genes are float32


def test_evolved_genes_are_the_last_parameters_outside_the_l2_penalty():
    policy = front_end(evolve=True, reservoir_lr=0.5)
    head = front_end().head
    assert policy.num_params == head.num_params + 3 and policy.penalised == slice(0, head.num_params)
    assert list(policy.layout.describe()) == ["fc1", "fc2", "fc3", "reservoir"]
    assert policy.layout.describe()["fc1"] == [128, UNITS]
    assert policy.roles == ("weights", "reservoir")
    params = policy.initial_params(np.random.default_rng(0))
    np.testing.assert_array_equal(params[-3:], genes(Hyperparameters(0.5, 1.0, 1.0)))
    assert policy.load(policy.export(params)).tobytes() == params.tobytes()


# --- training, resuming and evaluating ------------------------------------------------------------


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> dict[str, tuple[Path, str]]:
    """Each case of RUNS trained for 2 generations in this process: case -> (run folder, output)."""
    return {case: train(tmp_path_factory.mktemp("runs"), script, *RESERVOIR, *flags, "--generations", "2",
                        "--threads", "1") for case, (script, flags) in RUNS.items()}


@pytest.mark.parametrize("case", list(RUNS))
def test_two_workers_and_a_resume_build_the_same_reservoir(case, trained, tmp_path):
    script, flags = RUNS[case]
    expected = parameters_hash(trained[case][0])
    two_workers, _ = train(tmp_path / "two", script, *RESERVOIR, *flags, "--generations", "2", "--threads", "2")
    assert parameters_hash(two_workers) == expected
    resumed, _ = train(tmp_path / "resumed", script, *RESERVOIR, *flags, "--generations", "1", "--threads", "1")
    code, output = run(script, "--resume", resumed, "--generations", "2", "--threads", "2")
    assert code == 0, output[-3000:]
    assert parameters_hash(resumed) == expected
    other_reservoir, _ = train(tmp_path / "other", script, *RESERVOIR, *flags, "--reservoir_seed", "6",
                               "--generations", "2", "--threads", "1")
    assert parameters_hash(other_reservoir) != expected


def test_a_run_records_its_reservoir_and_evolves_its_genes(trained):
    run_dir, _ = trained["static, evolved reservoir"]
    config = json.loads((run_dir / "config.json").read_text())
    assert {key: config["policy"][key] for key in ("reservoir", "reservoir_units", "reservoir_evolve",
                                                   "reservoir_seed")} == {"reservoir": True, "reservoir_units": UNITS,
                                                                          "reservoir_evolve": True, "reservoir_seed": 5}
    assert config["layout"]["reservoir"] == [3] and config["layout"]["fc1"] == [128, UNITS]
    evolved = load_dat(run_dir / "last_reservoir.dat")
    assert evolved.shape == (3,) and not np.array_equal(evolved, genes(Hyperparameters(0.3, 1.0, 1.0)))
    assert len(list(run_dir.glob("CartPole-v1__rew_*__pop_8__reservoir__1.dat"))) == 1
    assert len(list(run_dir.glob("CartPole-v1__rew_*__pop_8__1.dat"))) == 1


def test_the_centres_evolved_hyperparameters_are_logged_and_in_the_metrics(trained):
    run_dir, output = trained["static, evolved reservoir"]
    rows = read_metrics(run_dir / "metrics.csv")
    decoded = hyperparameters(load_dat(run_dir / "last_reservoir.dat"))
    assert float(rows[-1]["reservoir_sr"]) == pytest.approx(decoded.spectral_radius, rel=1e-6)
    assert [float(row["reservoir_lr"]) > 0 for row in rows] == [True, True]
    assert f"reservoir: lr {float(rows[-1]['reservoir_lr']):.4g}, sr " in output
    given_dir, given_output = trained["hebbian, given reservoir"]
    assert "reservoir_lr" not in read_metrics(given_dir / "metrics.csv")[0] and "reservoir: lr" not in given_output


def evaluated_returns(script, *argv, json_path: Path) -> list[float]:
    code, output = run(script, *argv, "--episodes", "3", "--json", json_path)
    assert code == 0, output[-3000:]
    return json.loads(json_path.read_text())["environments"][0]["returns"]


@pytest.mark.parametrize("case, evaluate", [("static, evolved reservoir", evaluate_static.main),
                                            ("hebbian, given reservoir", evaluate_hebb.main)])
def test_a_trained_run_evaluates_with_the_printed_command_or_its_config(case, evaluate, trained, tmp_path):
    run_dir, output = trained[case]
    printed = shlex.split(output.strip().splitlines()[-1].split("evaluate with: ", 1)[1])[2:]
    printed = printed[:printed.index("--episodes")]
    assert printed[printed.index("--reservoir_seed") + 1] == "5"
    returns = evaluated_returns(evaluate, *printed, json_path=tmp_path / "printed.json")
    from_config = [word for index, word in enumerate(printed) if not word.startswith("--reservoir")
                   and not printed[index - 1].startswith("--reservoir")]  # the run folder's config.json instead
    assert evaluated_returns(evaluate, *from_config, json_path=tmp_path / "config.json") == returns
    seed_at = printed.index("--reservoir_seed")
    no_seed = printed[:seed_at] + printed[seed_at + 2:]  # the flags, but the seed from the run folder
    assert evaluated_returns(evaluate, *no_seed, json_path=tmp_path / "no_seed.json") == returns
    config = TrainConfig.from_dict(json.loads((run_dir / "config.json").read_text()))
    problem = ProblemSpec(("CartPole-v1",), config.policy).build()
    try:
        paths = {word: printed[index + 1] for index, word in enumerate(printed) if word.startswith("--path_")}
        arrays = {role: load_dat(paths[flag]) for role, flag in (("weights", "--path_weights"), ("coeffs", "--path_hebb"),
                                                                 ("reservoir", "--path_reservoir")) if flag in paths}
        params = problem.policy.load(arrays)
        assert [problem.evaluate(params, 0, seed).total_return for seed in range(3)] == returns
    finally:
        problem.close()


# --- what a user can get wrong ---------------------------------------------------------------------


@pytest.mark.parametrize("flags, message", [
    (("--reservoir_units", "50"), "--reservoir_units has an effect only with --reservoir; add --reservoir or leave "
                                  "--reservoir_units out"),
    (("--reservoir_evolve",), "--reservoir_evolve has an effect only with --reservoir"),
    (("--reservoir", "--reservoir_units", "0"), "--reservoir_units must be a whole number from 1 to 10000, got 0"),
    (("--reservoir", "--reservoir_lr", "1.5"), "--reservoir_lr (the leak rate) must be in (0, 1], got 1.5"),
    (("--reservoir", "--reservoir_sr", "-1"), "--reservoir_sr must be a number > 0, got -1.0"),
    (("--reservoir", "--reservoir_iss", "inf"), "--reservoir_iss must be a number > 0, got inf"),
    (("--reservoir", "--reservoir_evolve", "--reservoir_lr", "1"),
     "--reservoir_lr 1.0 is where --reservoir_evolve starts; it must lie strictly between ER-MRL's bounds 0.01 and 1"),
    (("--reservoir", "--reservoir_seed", "-3"), "argument --reservoir_seed: must be a whole number from 0 to"),
    (("--reservoir", "--environment", "CarRacing-v3"), "--reservoir reads observation vectors, but these observations "
                                                       "are images (3, 84, 84); leave --reservoir out"),
])
def test_bad_training_input_is_one_line_and_creates_nothing(flags, message, tmp_path):
    code, output = run(train_static.main, "--environment", "CartPole-v1", "--popsize", "2", *flags, "--generations",
                       "1", "--folder", tmp_path / "runs")
    assert code == 2 and len(output.strip().splitlines()) == 1, output
    assert message in output
    assert not (tmp_path / "runs").exists()


def test_a_resumed_run_keeps_its_reservoir(trained):
    run_dir, _ = trained["static, evolved reservoir"]
    code, output = run(train_static.main, "--resume", run_dir, "--reservoir_sr", "0.5", "--generations", "3")
    assert code == 2 and "--reservoir_sr 0.5 (the run has 1.0)" in output


def test_bad_evaluation_input_is_one_line(trained, tmp_path):
    run_dir, _ = trained["static, evolved reservoir"]
    weights, outside = run_dir / "last.dat", tmp_path / "weights.dat"
    save_dat(outside, load_dat(weights))
    short = tmp_path / "short.dat"
    save_dat(short, np.zeros(2, np.float32))
    base = ("--environment", "CartPole-v1")
    for argv, message in [
        ((*base, "--path_weights", weights), "these weights were trained with --reservoir_evolve: pass the run's "
                                             "evolved reservoir hyperparameters too, --path_reservoir"),
        ((*base, "--path_weights", outside, "--reservoir"), "--reservoir needs --reservoir_seed"),
        ((*base, "--path_weights", outside, "--reservoir_seed", "5"), "--reservoir_seed has an effect only with "
                                                                      "--reservoir"),
        ((*base, "--path_weights", weights, "--path_reservoir", short),
         "the --path_reservoir file holds shape (2,), but the reservoir's genes (lr, sr, iss) needs 3 values"),
    ]:
        code, output = run(evaluate_static.main, *argv)
        errors = [line for line in output.splitlines() if "error:" in line]
        assert code == 2 and len(errors) == 1 and message in errors[0] and output.strip().endswith(errors[0]), output


# --- the comparison runner and its environment ------------------------------------------------------


def test_cartpole_without_velocities_is_cartpole_seen_through_positions():
    import gymnasium as gym

    from experiments.reservoir_front.partial import ENV_ID

    full, partial = gym.make("CartPole-v1"), gym.make(ENV_ID)
    try:
        assert partial.observation_space.shape == (2,) and partial.spec.max_episode_steps == 500
        observation, _ = full.reset(seed=3)
        seen, _ = partial.reset(seed=3)
        np.testing.assert_array_equal(seen, observation[[0, 2]])
        for action in [0, 1, 1, 0, 1] * 4:
            observation, reward, terminated, truncated, _ = full.step(action)
            assert partial.step(action)[1:4] == (reward, terminated, truncated)
            np.testing.assert_array_equal(partial.unwrapped.state[[0, 2]].astype(np.float32), observation[[0, 2]])
    finally:
        full.close()
        partial.close()


def test_the_comparison_runner_trains_evaluates_and_tabulates(tmp_path):
    from experiments.reservoir_front import compare

    code, output = run(compare.main, "--arms", "static", "static+evolved", "--seeds", "2", "--generations", "2",
                       "--popsize", "4", "--units", "5", "--episodes", "3", "--threads", "1", "--folder", tmp_path,
                       "--", "--optimizer", "adam")
    assert code == 0, output[-3000:]
    results = json.loads((tmp_path / "results.json").read_text())
    for arm in ("static", "static+evolved"):
        evaluation = json.loads((only_run(tmp_path / f"{arm}_seed2") / "evaluation.json").read_text())
        assert results[arm]["2"] == evaluation and len(evaluation["environments"][0]["returns"]) == 3
        mean = np.mean(evaluation["environments"][0]["returns"])
        assert f"| {arm} | {mean:.1f} | **{mean:.1f}** |\n" in (tmp_path / "results.md").read_text()
    config = json.loads((only_run(tmp_path / "static+evolved_seed2") / "config.json").read_text())
    assert config["policy"]["reservoir_evolve"] and config["es"]["optimizer"] == "adam"
    assert not json.loads((only_run(tmp_path / "static_seed2") / "config.json").read_text())["policy"]["reservoir"]
    before = (tmp_path / "results.md").read_text()  # again: nothing retrained or re-evaluated, the same table
    code, output = run(compare.main, "--arms", "static", "static+evolved", "--seeds", "2", "--generations", "2",
                       "--popsize", "4", "--units", "5", "--episodes", "3", "--threads", "1", "--folder", tmp_path)
    assert code == 0 and (tmp_path / "results.md").read_text() == before and "evaluate_" not in output


def test_reservoir_alone_on_evaluation_takes_the_rest_from_the_run_folder(trained, tmp_path):
    run_dir, output = trained["hebbian, given reservoir"]
    printed = shlex.split(output.strip().splitlines()[-1].split("evaluate with: ", 1)[1])[2:]
    printed = printed[:printed.index("--episodes")]
    returns = evaluated_returns(evaluate_hebb.main, *printed, json_path=tmp_path / "printed.json")
    bare = [word for index, word in enumerate(printed) if not word.startswith("--reservoir_")
            and not printed[index - 1].startswith("--reservoir_")]  # --reservoir, units, lr, sr and seed left out
    assert "--reservoir" in bare
    assert evaluated_returns(evaluate_hebb.main, *bare, json_path=tmp_path / "bare.json") == returns
    evolved_dir, _ = trained["static, evolved reservoir"]
    code, output = run(evaluate_static.main, "--environment", "CartPole-v1", "--path_weights", evolved_dir / "last.dat",
                       "--reservoir")
    assert code == 2 and "pass the run's evolved reservoir hyperparameters too, --path_reservoir" in output
