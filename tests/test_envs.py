"""Environment construction (envs/make.py), observation pipelines and rollout determinism.

Covers: retired ids of the original code (CarRacing-v0, LunarLander-v2, BipedalWalker-v2, and the
mujoco-py Ant-v2 that Gymnasium keeps registered but cannot make) mapped to current versions with a
one-line notice; unknown ids refused with close matches; custom environments in Gymnasium's
``module:EnvId`` form; headless MuJoCo; one-hot Discrete observations; the CarRacing pixel pipeline
(84x84, [0, 1], transposed like the original's ``swapaxes(0, 2)``); and that one rollout of the same
parameters and seed gives the same return, including on a reused pyBullet environment.
"""

from __future__ import annotations

import cv2
import gymnasium as gym
import numpy as np
import pytest

import envs
from envs import EnvironmentError_, ProblemSpec, make_env, resolve_env_id, rollout
from envs.problem import network_spec
from policies import PolicySettings, make_policy
from tests import custom_env_module


@pytest.mark.parametrize("retired, current", [
    ("CarRacing-v0", "CarRacing-v3"),
    ("LunarLander-v2", "LunarLander-v3"),
    ("BipedalWalker-v2", "BipedalWalker-v3"),
])
def test_retired_ids_map_to_the_current_version_with_a_one_line_notice(retired, current):
    with pytest.raises(gym.error.DeprecatedEnv):
        gym.make(retired)  # what the original command line would hit on Gymnasium 1.x
    notices = []
    assert resolve_env_id(retired, notify=notices.append) == current
    assert len(notices) == 1 and "\n" not in notices[0]
    assert retired in notices[0] and current in notices[0]


def test_registered_but_unusable_mujoco_py_id_maps_to_the_newest_usable_version():
    assert "Ant-v2" in gym.registry
    with pytest.raises(ImportError):
        gym.make("Ant-v2")  # mujoco-py based: registered, but it raises
    notices = []
    assert resolve_env_id("Ant-v2", notify=notices.append) == "Ant-v5"
    assert len(notices) == 1 and "Ant-v5" in notices[0]


@pytest.mark.parametrize("env_id", ["CartPole-v1", "Ant-v4", "AntBulletEnv-v0", "HalfCheetah-v5"])
def test_current_ids_resolve_to_themselves_silently(env_id):
    notices = []
    assert resolve_env_id(env_id, notify=notices.append) == env_id
    assert notices == []


@pytest.mark.parametrize("env_id, suggestion", [
    ("CartPol-v1", "CartPole-v1"),
    ("AntBulletEnv-v0x", "AntBulletEnv-v0"),
    ("Lunarlander-v3", "LunarLander-v3"),
])
def test_unknown_ids_raise_with_close_matches(env_id, suggestion):
    with pytest.raises(EnvironmentError_, match="did you mean") as raised:
        resolve_env_id(env_id, notify=pytest.fail)
    message = str(raised.value)
    assert repr(env_id) in message and suggestion in message and "\n" not in message
    assert isinstance(raised.value, ValueError)


def test_unknown_id_without_close_match_points_to_the_registry():
    with pytest.raises(EnvironmentError_, match="pprint_registry"):
        resolve_env_id("Qqqqqqqqqqqq-v0")


def test_unimportable_module_is_named():
    with pytest.raises(EnvironmentError_, match="no_such_module_for_tests"):
        resolve_env_id("no_such_module_for_tests:Thing-v0")


def test_custom_environment_in_module_colon_id_form():
    env_id = f"tests.custom_env_module:{custom_env_module.ENV_ID}"
    resolved = resolve_env_id(env_id, notify=pytest.fail)
    assert resolved.endswith(custom_env_module.ENV_ID)
    env, recipe = make_env(resolved)
    assert recipe.name == "Gymnasium"
    net = network_spec(env, recipe)
    assert net.obs_shape == (2,) and net.n_actions == 2
    policy = make_policy(PolicySettings(), net, recipe.normalise_hebbian)
    params = policy.initial_params(np.random.default_rng(0))
    episode = rollout(env, policy, params, seed=0)
    assert episode.steps == custom_env_module.MAX_STEPS  # the registered TimeLimit applies
    assert abs(episode.total_return) <= custom_env_module.MAX_STEPS and episode.total_return % 1 == 0


def test_mujoco_half_cheetah_makes_and_steps_headless():
    env, recipe = make_env("HalfCheetah-v5")
    try:
        assert recipe.name == "Gymnasium"
        observation, _ = env.reset(seed=0)
        assert observation.shape == (17,)
        for t in range(5):
            observation, reward, terminated, truncated, _ = env.step(np.full(6, 3.0 * (-1) ** t, np.float32))
        assert np.all(np.isfinite(observation)) and np.isfinite(reward) and not (terminated or truncated)
        assert env.action_space.shape == (6,) and env.unwrapped.action_space.high.max() == 1.0
    finally:
        env.close()


def test_discrete_observations_are_one_hot():
    env, _ = make_env("FrozenLake-v1")
    observation, _ = env.reset(seed=0)
    assert observation.dtype == np.float32 and observation.shape == (16,)
    np.testing.assert_array_equal(observation, np.eye(16, dtype=np.float32)[0])
    visited = set()
    for output in ([0, 0, 1, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 1, 0, 0]):  # right, down, ...
        observation, _, terminated, truncated, _ = env.step(np.array(output, np.float32))
        state = int(env.unwrapped.s)
        np.testing.assert_array_equal(observation, np.eye(16, dtype=np.float32)[state])
        visited.add(state)
        if terminated or truncated:
            break
    assert visited - {0}  # the agent moved, and the observation followed it
    env.close()


def test_car_racing_pixels_are_84x84_floats_in_0_1_transposed_like_the_original():
    env, _ = make_env("CarRacing-v3")
    with envs.quiet_output():
        raw = gym.make("CarRacing-v3")
    try:
        observation, _ = env.reset(seed=2)
        frame, _ = raw.reset(seed=2)
        assert observation.shape == (3, 84, 84) and observation.dtype == np.float32
        assert observation.min() >= 0.0 and observation.max() <= 1.0 and observation.std() > 0
        resized = cv2.resize(frame, (84, 84), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
        np.testing.assert_allclose(observation, np.swapaxes(resized, 0, 2), rtol=0, atol=1e-6)
        assert not np.allclose(observation, np.transpose(resized, (2, 0, 1)))  # (C, W, H), not (C, H, W)
    finally:
        env.close()
        raw.close()


@pytest.mark.parametrize("kind", ["static", "hebbian"])
def test_rollout_is_deterministic_for_the_same_params_and_seed(kind):
    problem = ProblemSpec(("CartPole-v1",), PolicySettings(kind)).build()
    other = ProblemSpec(("CartPole-v1",), PolicySettings(kind)).build()
    try:
        params = problem.policy.initial_params(np.random.default_rng(3))
        first = problem.evaluate(params, 0, seed=11)
        problem.evaluate(params, 0, seed=12)  # an episode in between must not matter
        assert problem.evaluate(params, 0, seed=11) == first
        assert other.evaluate(params, 0, seed=11) == first  # nor which process/env runs it
    finally:
        problem.close()
        other.close()


def test_pybullet_ant_rollout_is_the_same_on_a_fresh_and_a_reused_env():
    """pyBullet's first reset loads the model and later ones restore a state; make_env's warm-up
    reset makes a fresh environment behave like a reused one."""
    problem = ProblemSpec(("AntBulletEnv-v0",), PolicySettings("static")).build()
    fresh = ProblemSpec(("AntBulletEnv-v0",), PolicySettings("static")).build()
    try:
        params = problem.policy.initial_params(np.random.default_rng(0))
        first = problem.evaluate(params, 0, seed=5)
        again = problem.evaluate(params, 0, seed=5)
        assert again == first
        assert fresh.evaluate(params, 0, seed=5) == first
        assert first.steps > 40  # the ant walked (or fell) after its burn-in
    finally:
        problem.close()
        fresh.close()
