"""ER-MRL's pieces (reservoirs/): the echo state network against reservoirpy 0.3 and against the
equations, the wrappers on real CartPole-v1, Pendulum-v1 and LunarLander-v3, the normalised score, the
search space and the samplers. The command lines are in test_reservoir_scripts.py.

Skipped where the optional extra is not installed (pip install -r requirements-reservoirs.txt).
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from tests.extras import need_module_level

need_module_level("reservoirs")

from policies.reservoir_matrices import CONNECTIVITY, ReservoirMatrices  # noqa: E402
from reservoirs import experiments  # noqa: E402
from reservoirs.esn import EchoStateNetwork, ReservoirSettings  # noqa: E402
from reservoirs.study import make_sampler, process_seed, study_name  # noqa: E402
from reservoirs.wrappers import (  # noqa: E402
    DeletedVelocityWrapper,
    MultiReservoirWrapper,
    POReservoirWrapper,
    ReservoirWrapper,
    RewardsSavingWrapper,
)

ROOT = Path(__file__).resolve().parent.parent

SETTINGS = ReservoirSettings(units=50, leak_rate=0.3, spectral_radius=1.7, input_scaling=2.5)


def plain_loop(weights, input_weights, bias, leak_rate, inputs, reset_after=None) -> np.ndarray:
    """x[t+1] = (1 - lr) x[t] + lr tanh(W_in u[t+1] + W x[t] + b), from x = 0; zeroed after step reset_after."""
    state = np.zeros(weights.shape[0])
    states = []
    for step, row in enumerate(inputs):
        state = (1 - leak_rate) * state + leak_rate * np.tanh(input_weights @ row + weights @ state + bias)
        states.append(state)
        if step == reset_after:
            state = np.zeros_like(state)
    return np.array(states)


# --- the echo state network -----------------------------------------------------------------------


REPRODUCE_0_3 = """
import numpy as np
from reservoirs.esn import EchoStateNetwork, ReservoirSettings
from tests import reservoirpy03_fixture as fixture

expected = np.load(fixture.FIXTURE)
settings = ReservoirSettings(fixture.UNITS, fixture.LEAK_RATE, fixture.SPECTRAL_RADIUS, fixture.INPUT_SCALING)
network = EchoStateNetwork(fixture.INPUT_DIM, settings, fixture.SEED)
for matrix, name in zip(network.matrices(), ("W", "Win", "bias")):
    np.testing.assert_array_equal(matrix, expected[name])
states = []
for step, row in enumerate(fixture.inputs()):
    states.append(network.step(row))
    if step == fixture.RESET_AFTER:
        network.reset()
np.testing.assert_array_equal(np.array(states), expected["states"])
"""


def test_reproduces_reservoirpy_0_3_bit_for_bit():
    """The matrices and states reservoirpy 0.3.9.post1 (ER-MRL's version) computed for the same reservoir, with
    the BLAS kernel it was computed with (OpenBLAS's Haswell one): the spectral radius that scales W comes from
    an eigensolver whose last bits follow the BLAS kernel (docs/reproducibility.md), so the check runs in a
    process that asks for that kernel, on any x86-64 CPU with AVX2."""
    if platform.machine() not in ("x86_64", "AMD64"):
        pytest.skip("the fixture was computed with OpenBLAS's x86-64 Haswell kernel")
    result = subprocess.run([sys.executable, "-c", REPRODUCE_0_3], cwd=ROOT, capture_output=True, text=True,
                            timeout=120, env={**os.environ, "OPENBLAS_CORETYPE": "Haswell"})
    assert result.returncode == 0, result.stderr[-3000:]


@pytest.mark.parametrize("leak_rate", [0.3, 1.0])
def test_step_is_the_leaky_integrator_equation(leak_rate):
    settings = ReservoirSettings(50, leak_rate, 1.7, 2.5)
    network = EchoStateNetwork(6, settings, seed=4)
    inputs = np.random.default_rng(1).normal(size=(40, 6))
    states = []
    for step, row in enumerate(inputs):
        states.append(network.step(row))
        if step == 19:
            network.reset()
            np.testing.assert_array_equal(network.state, np.zeros(50))
    expected = plain_loop(*network.matrices(), leak_rate, inputs, reset_after=19)
    np.testing.assert_allclose(np.array(states), expected, rtol=1e-12, atol=1e-14)


def test_matrices_have_the_0_3_structure():
    """10 % connectivity, W rescaled to the spectral radius, W_in = ±iss, bias = ±1."""
    weights, input_weights, bias = EchoStateNetwork(6, SETTINGS, seed=1).matrices()
    assert np.count_nonzero(weights) == 250  # 10 % of 50 x 50
    assert np.count_nonzero(input_weights) == 30  # 10 % of 50 x 6
    assert np.count_nonzero(bias) == 5  # 10 % of 50
    assert np.max(np.abs(np.linalg.eigvals(weights))) == pytest.approx(1.7, rel=1e-9)
    assert set(np.unique(input_weights)) == {-2.5, 0.0, 2.5}
    assert set(np.unique(bias)) == {-1.0, 0.0, 1.0}


@pytest.mark.parametrize("units, seed", [(3, 7), (5, 7), (50, 2)])  # (5, 7): a nilpotent W, whose radius is floored
def test_drawn_matrices_rescale_to_mat_gen_s_bit_for_bit(units, seed):
    """Drawn once and rescaled, the matrices are those mat_gen makes for each (sr, iss) (policies.reservoir)."""
    from reservoirpy import mat_gen

    drawn = ReservoirMatrices.generate(units, 6, seed)
    for spectral_radius, input_scaling in ((0.1, 1.0), (1.7, 2.5), (50.0, 0.13)):
        weights, input_weights, _ = drawn.scaled(spectral_radius, input_scaling)
        expected = mat_gen.normal(units, units, connectivity=CONNECTIVITY, sr=spectral_radius, seed=seed)
        np.testing.assert_array_equal(weights.toarray(), expected.toarray())
        expected = mat_gen.bernoulli(units, 6, connectivity=CONNECTIVITY, input_scaling=input_scaling, seed=seed)
        np.testing.assert_array_equal(input_weights.toarray(), expected.toarray())


@pytest.mark.parametrize("units", [1, 2])
def test_one_or_two_units_build(units):
    """ARPACK needs 3 units; below, the radius comes from the dense eigenvalues (reservoirpy raised a TypeError)."""
    network = EchoStateNetwork(4, ReservoirSettings(units, 0.5, 0.9), seed=1)
    expected = plain_loop(*network.matrices(), 0.5, np.ones((3, 4)))
    np.testing.assert_allclose(np.array([network.step(np.ones(4)) for _ in range(3)]), expected, rtol=1e-12)


def test_same_seed_same_reservoir_other_seed_other():
    first, again, other = (EchoStateNetwork(6, SETTINGS, seed).matrices()[0] for seed in (3, 3, 4))
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)


def test_bad_settings_and_inputs_are_refused():
    with pytest.raises(ValueError, match="leak rate must be in"):
        ReservoirSettings(10, 1.5, 1.0)
    with pytest.raises(ValueError, match="spectral radius must be a number > 0"):
        ReservoirSettings(10, 0.5, 0.0)
    with pytest.raises(ValueError, match=r"input must have shape \(6,\)"):
        EchoStateNetwork(6, SETTINGS, 0).step(np.zeros(5))


# --- wrappers -------------------------------------------------------------------------------------

# env id -> (observation size, action size in the reservoir's input)
SIZES = {"CartPole-v1": (4, 2), "Pendulum-v1": (3, 1)}


def check_shapes(env: gym.Env, size: int) -> None:
    assert env.observation_space.shape == (size,)
    context, _ = env.reset(seed=0)
    assert context.shape == (size,) and context.dtype == np.float64
    context, *_ = env.step(env.action_space.sample())
    assert context.shape == (size,)


@pytest.mark.parametrize("env_id", SIZES)
def test_wrapper_observation_shapes(env_id):
    observation, action = SIZES[env_id]
    inputs = observation + action + 1
    small = ReservoirSettings(20, 0.5, 1.0)
    check_shapes(ReservoirWrapper(gym.make(env_id), small, seed=0), 20)
    check_shapes(ReservoirWrapper(gym.make(env_id), small, seed=0, skip_c=True), 20 + inputs)
    check_shapes(MultiReservoirWrapper(gym.make(env_id), [small, ReservoirSettings(7, 0.2, 3.0)], seed=0), 27)
    check_shapes(MultiReservoirWrapper(gym.make(env_id), [small, small], seed=0, skip_c=True), 40 + inputs)
    check_shapes(POReservoirWrapper(gym.make(env_id), small, obs_units=8, seed=0), 8)


def test_context_lies_in_its_space():
    env = ReservoirWrapper(gym.make("CartPole-v1"), SETTINGS, seed=0)
    context, _ = env.reset(seed=0)
    done = False
    while not done:
        assert env.observation_space.contains(context)
        context, _, terminated, truncated, _ = env.step(1)
        done = terminated or truncated


def test_skip_connection_bounds_use_max():
    """The original took min(observation_space.high) for a Discrete action space (docs/original.md, "ER-MRL")."""
    discrete = ReservoirWrapper(gym.make("CartPole-v1"), SETTINGS, skip_c=True)
    cartpole = gym.make("CartPole-v1").observation_space
    assert discrete.observation_space.high[0] == np.float64(np.max(cartpole.high))
    assert discrete.observation_space.low[0] == np.float64(np.min(cartpole.low))
    box = ReservoirWrapper(gym.make("Pendulum-v1"), SETTINGS, skip_c=True)
    assert (box.observation_space.low[0], box.observation_space.high[0]) == (-8.0, 8.0)  # Pendulum's speed


@pytest.mark.parametrize("env_id, kept", [("CartPole-v1", 2), ("Pendulum-v1", 2), ("LunarLander-v3", 5),
                                          ("MountainCarContinuous-v0", 1)])
def test_deleted_velocity_shapes(env_id, kept):
    env = DeletedVelocityWrapper(gym.make(env_id))
    assert env.observation_space.shape == (kept,)
    observation, _ = env.reset(seed=0)
    assert observation.shape == (kept,)


def test_deleted_velocity_removes_the_original_indices():
    plain, masked = gym.make("CartPole-v1"), DeletedVelocityWrapper(gym.make("CartPole-v1"))
    full, _ = plain.reset(seed=3)
    kept, _ = masked.reset(seed=3)
    np.testing.assert_array_equal(kept, full[[0, 2]])  # position and angle; velocities 1 and 3 gone


def test_deleted_velocity_names_the_environments_it_knows():
    with pytest.raises(ValueError, match="CartPole, MountainCar.*not Acrobot"):
        DeletedVelocityWrapper(gym.make("Acrobot-v1"))


def replay(env: ReservoirWrapper, actions) -> tuple[list, list]:
    """(context, what the reservoir read) after the reset and after each action."""
    context, _ = env.reset(seed=5)
    contexts, inputs = [context], [env.last_input]
    for action in actions:
        context, *_ = env.step(action)
        contexts.append(context)
        inputs.append(env.last_input)
    return contexts, inputs


def test_reservoir_reads_the_previous_discrete_action_one_hot():
    env = ReservoirWrapper(gym.make("CartPole-v1"), SETTINGS, seed=2)
    twin = gym.make("CartPole-v1")
    observation, _ = twin.reset(seed=5)
    network = EchoStateNetwork(4 + 2 + 1, SETTINGS, seed=2)
    actions = [1, 0, 1, 1, 0]
    contexts, inputs = replay(env, actions)
    expected = [network.step(np.concatenate((observation, [0, 0], [0.0])))]  # no action yet at the reset
    np.testing.assert_array_equal(inputs[0][4:], [0, 0, 0])
    for action, read in zip(actions, inputs[1:]):
        observation, reward, *_ = twin.step(action)
        code = np.eye(2)[action]
        np.testing.assert_array_equal(read, np.concatenate((observation, code, [reward])))
        expected.append(network.step(read))
    np.testing.assert_allclose(np.array(contexts), np.array(expected), rtol=0, atol=0)


def test_reservoir_reads_the_previous_box_action():
    env = ReservoirWrapper(gym.make("Pendulum-v1"), SETTINGS, seed=2)
    actions = [np.array([1.5], dtype=np.float32), np.array([-0.25], dtype=np.float32)]
    _, inputs = replay(env, actions)
    assert [read[3] for read in inputs] == [0.0, 1.5, -0.25]


def test_zero_action_reproduces_the_published_input():
    """The original overwrote the action: one-hot(0) for Discrete (also at the reset), zeros for Box."""
    _, inputs = replay(ReservoirWrapper(gym.make("CartPole-v1"), SETTINGS, zero_action=True), [1, 1, 0])
    assert [list(read[4:6]) for read in inputs] == [[1, 0]] * 4
    _, inputs = replay(ReservoirWrapper(gym.make("Pendulum-v1"), SETTINGS, zero_action=True), [np.array([2.0])])
    assert [read[3] for read in inputs] == [0.0, 0.0]


def test_action_changes_the_context():
    first, _ = replay(ReservoirWrapper(gym.make("CartPole-v1"), SETTINGS, seed=2), [1])
    second, _ = replay(ReservoirWrapper(gym.make("CartPole-v1"), SETTINGS, seed=2), [0])
    np.testing.assert_array_equal(first[0], second[0])
    assert not np.allclose(first[1], second[1])
    published = [replay(ReservoirWrapper(gym.make("CartPole-v1"), SETTINGS, seed=2, zero_action=True), [action])[1]
                 for action in (0, 1)]
    np.testing.assert_array_equal(published[0][1][4:], published[1][1][4:])  # the action never reached it


def test_reservoir_is_reset_every_episode():
    env = ReservoirWrapper(gym.make("CartPole-v1"), SETTINGS, seed=2)
    first, _ = env.reset(seed=9)
    for _ in range(5):
        changed, *_ = env.step(1)
    assert not np.array_equal(first, changed)
    again, _ = env.reset(seed=9)
    np.testing.assert_array_equal(first, again)


def test_multi_reservoir_seeds_are_seed_plus_index():
    env = MultiReservoirWrapper(gym.make("CartPole-v1"), [SETTINGS, SETTINGS], seed=10)
    single = ReservoirWrapper(gym.make("CartPole-v1"), SETTINGS, seed=11)
    np.testing.assert_array_equal(env.reservoirs[1].matrices()[0], single.reservoirs[0].matrices()[0])
    context, _ = env.reset(seed=0)
    alone, _ = single.reset(seed=0)
    np.testing.assert_array_equal(context[50:], alone)


def test_rewards_saving_wrapper_keeps_finished_episodes():
    env = RewardsSavingWrapper(gym.make("CartPole-v1"))
    assert np.isnan(env.mean_reward(10))
    lengths = []
    for episode in range(3):
        env.reset(seed=episode)
        steps, done = 0, False
        while not done:
            _, _, terminated, truncated, _ = env.step(1)
            steps, done = steps + 1, terminated or truncated
        lengths.append(steps)
    env.reset(seed=3)
    env.step(1)  # an unfinished episode does not count
    assert env.episode_returns == [float(length) for length in lengths]  # CartPole: +1 per step
    assert env.mean_reward(2) == np.mean(lengths[1:])


# --- search space, score, samplers ----------------------------------------------------------------


def test_normalised_score():
    assert experiments.normalised_score(125, "Ant-v4", "per_step") == 1.0
    assert experiments.normalised_score(-0.355, "Ant-v4", "per_step") == 0.0
    assert experiments.normalised_score(30.0, "Swimmer-v4", "per_step") == 0.5
    random_return = experiments.RANDOM_RETURN_EPISODIC["HalfCheetah-v4"]
    assert experiments.normalised_score(random_return, "HalfCheetah-v4") == 0.0
    assert experiments.normalised_score(750, "HalfCheetah-v4") == 1.0


def test_every_target_has_both_random_returns():
    assert set(experiments.TARGET_RETURN) <= set(experiments.RANDOM_RETURN_EPISODIC)
    assert set(experiments.TARGET_RETURN) <= set(experiments.RANDOM_RETURN_PER_STEP)


def test_env_types():
    assert experiments.env_ids_for("Ant_Swimmer") == ("Ant-v4", "Swimmer-v4")
    assert experiments.env_ids_for("Hopper_4_tr_envs") == ("Ant-v4", "HalfCheetah-v4", "Swimmer-v4", "Walker2d-v4")
    assert experiments.env_ids_for("Hopper-v4, Swimmer-v4") == ("Hopper-v4", "Swimmer-v4")
    for bad in ("Ant", "Ant-v4", "Ant-v4,CartPole-v1"):
        with pytest.raises(ValueError, match="unknown --env_type .*valid: Ant_Swimmer"):
            experiments.env_ids_for(bad)


def test_search_space_names_and_order():
    bounds = {"sr": (1e-4, 1e2), "lr": (1e-2, 1.0), "iss": (0.1, 10.0)}
    assert experiments.SearchSpace(bounds, 100).searched() == ["sr", "lr"]
    assert experiments.SearchSpace(bounds, 100, fixed_iss=False).searched() == ["iss", "sr", "lr"]
    several = experiments.SearchSpace(bounds, 100, nb_res=2, fixed_iss=False, suffixed=True)
    assert several.searched() == ["lr_1", "lr_2", "sr_1", "sr_2", "iss_1", "iss_2"]
    with pytest.raises(ValueError, match="--max_lr 2.0: a leak rate is at most 1"):
        experiments.SearchSpace({**bounds, "lr": (0.1, 2.0)}, 100)
    with pytest.raises(ValueError, match="--min_sr 5.0 and --max_sr 1.0"):
        experiments.SearchSpace({**bounds, "sr": (5.0, 1.0)}, 100)


def test_reservoirs_from_params():
    params = {"lr_1": 0.5, "lr_2": 0.25, "sr_1": 2.0, "sr_2": 0.5}
    assert experiments.reservoirs_from_params(params, 30, 2, True, True) == [
        ReservoirSettings(30, 0.5, 2.0, 1.0), ReservoirSettings(30, 0.25, 0.5, 1.0)]
    with pytest.raises(ValueError, match="lack iss_1, iss_2 \\(was it evolved with --fixed_iss True\\?\\)"):
        experiments.reservoirs_from_params(params, 30, 2, False, True)


def test_study_names_follow_the_original():
    assert study_name("HalfCheetah-v4", "exp", training_steps=300000) == "HalfCheetah-v4_exp_300k_steps"
    assert study_name("Ant_Swimmer", 2, "gen", training_steps=300999) == "Ant_Swimmer_2_gen_300k_steps"


def test_process_seed():
    assert process_seed(None, 5) is None
    assert process_seed(1, 0) == process_seed(1, 0)
    assert len({process_seed(1, 0), process_seed(1, 2), process_seed(2, 0)}) == 3


def test_cma_es_restarts_with_a_larger_population():
    """IPOP is real: optuna >= 4.4 accepts restart_strategy='ipop' and ignores it, which this catches."""
    import optuna

    sampler = make_sampler("Cmaes", seed=0)
    assert isinstance(sampler, optuna.samplers.CmaEsSampler)
    study = optuna.create_study(sampler=sampler)
    # a flat objective: after 10 + 30 * 2 / 6 = 20 generations of 6 without progress CMA-ES stops (tolfun),
    # and IPOP restarts it with twice the population (trial 127)
    study.optimize(lambda trial: 0.0 * trial.suggest_float("x", 1, 2) * trial.suggest_float("y", 1, 2), n_trials=130)
    population_sizes = [trial.system_attrs.get("cma:ipop:popsize") for trial in study.trials]
    assert population_sizes[1:127] == [6] * 126 and population_sizes[127:] == [12] * 3


def test_unknown_sampler():
    with pytest.raises(ValueError, match="unknown sampler 'Grid'; valid: Random, Tpe, Cmaes"):
        make_sampler("Grid", None)
