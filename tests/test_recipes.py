"""Per-family environment recipes (envs/recipes.py) and their wrappers (envs/wrappers.py).

The original code chose each quirk by exact id inside its episode loop (docs/original.md, "Episodes"):
argmax for Discrete actions, clipping for Box, [tanh, sigmoid, sigmoid] and a stop on the 21st
consecutive negative reward for CarRacing, and for the pyBullet ant a tanh output, a 40-step
zero-action burn-in, the progress reward ``rewards[1]``, termination ignored for the first 201
steps and a stop on the 31st consecutive negative reward after them. These tests run each recipe
on the real environment, with a logging wrapper *under* the recipe's wrappers that records what
the environment itself received and returned; where an exact schedule is clearer, the wrappers
run on a scripted stub environment instead.
"""

from __future__ import annotations

import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

import envs
from envs import ProblemSpec, make_env, recipe_for, resolve_env_id, rollout
from envs.problem import network_spec
from envs.wrappers import BurnIn, NegativeRewardStop, PixelObservation
from policies import PolicySettings

ROOT = Path(__file__).resolve().parent.parent


class EnvLog(gym.Wrapper):
    """Records, beneath the recipe's wrappers, every action the environment received and its step."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.actions: list = []
        self.rewards: list[float] = []
        self.terminated: list[bool] = []
        self.progress: list[float] = []  # pyBullet walkers: the unwrapped env's rewards[1]

    def reset(self, **kwargs):
        for records in (self.actions, self.rewards, self.terminated, self.progress):
            records.clear()
        return self.env.reset(**kwargs)

    def step(self, action):
        observation, reward, terminated, truncated, info = self.env.step(action)
        self.actions.append(np.array(action, copy=True))
        self.rewards.append(float(reward))
        self.terminated.append(bool(terminated))
        if hasattr(self.env.unwrapped, "rewards"):
            self.progress.append(float(self.env.unwrapped.rewards[1]))
        return observation, reward, terminated, truncated, info


def logged(env_id: str) -> tuple[gym.Env, EnvLog]:
    """The environment as ``make_env`` wraps it, with an ``EnvLog`` between it and its recipe."""
    with envs.quiet_output():
        log = EnvLog(gym.make(env_id))
        env = recipe_for(log).wrap(log)
    return env, log


class ConstantPolicy:
    """A policy protocol stand-in whose output is fixed: the rollout still runs unchanged."""

    def __init__(self, output):
        self.output = np.asarray(output, dtype=np.float32)

    def reset(self, params, rng):
        return None

    def act(self, params, state, observation):
        return self.output, state


def longest_run(flags) -> int:
    longest = current = 0
    for flag in flags:
        current = current + 1 if flag else 0
        longest = max(longest, current)
    return longest


def sigmoid(x: float) -> float:
    return 1.0 / (1.0 + math.exp(-x))


# --- Gymnasium families: argmax for Discrete, clip for Box ---------------------------------------


@pytest.mark.parametrize("env_id, outputs, expected", [
    ("CartPole-v1", [[0.3, -1.0], [-2.0, 5.0], [1.0, 1.0]], [0, 1, 0]),
    ("LunarLander-v3", [[0.0, 0.0, 0.0, 9.0], [-1.0, 3.0, 2.9, 0.0], [0.0, -1.0, 0.5, 0.4]], [3, 1, 2]),
])
def test_discrete_actions_are_the_argmax_of_the_output(env_id, outputs, expected):
    env, log = logged(env_id)
    env.reset(seed=1)
    for output in outputs:
        env.step(np.array(output, dtype=np.float32))
    assert [int(action) for action in log.actions] == expected
    _, recipe = make_env(env_id)
    assert recipe.name == "Gymnasium" and not recipe.squash_output and recipe.normalise_hebbian
    assert env.action_space.shape == (len(outputs[0]),)  # the network has one output per action


@pytest.mark.parametrize("env_id, outputs, expected", [
    ("Pendulum-v1", [[5.0], [-0.5], [-9.0]], [[2.0], [-0.5], [-2.0]]),
    ("LunarLanderContinuous-v3", [[3.0, -0.2], [-4.0, 0.7], [0.25, -1.5]], [[1.0, -0.2], [-1.0, 0.7], [0.25, -1.0]]),
])
def test_box_actions_are_clipped_to_the_bounds(env_id, outputs, expected):
    env, log = logged(env_id)
    env.reset(seed=1)
    for output in outputs:
        env.step(np.array(output, dtype=np.float32))
    np.testing.assert_allclose(np.array(log.actions, dtype=np.float64), expected, rtol=0, atol=1e-7)
    _, recipe = make_env(env_id)
    assert recipe.name == "Gymnasium" and not recipe.squash_output


# --- CarRacing -----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def car_racing_episode():
    """One real CarRacing-v3 episode of a car that brakes and never accelerates."""
    env, log = logged("CarRacing-v3")
    env.reset(seed=3)
    output = np.array([0.5, -3.0, 2.0], dtype=np.float32)
    steps = []
    for _ in range(200):  # stops after ~21 steps; the bound only guards against a hang
        steps.append(env.step(output))
        if steps[-1][2] or steps[-1][3]:
            break
    yield steps, log
    env.close()


def test_car_racing_action_is_tanh_sigmoid_sigmoid(car_racing_episode):
    _, log = car_racing_episode
    np.testing.assert_allclose(log.actions[0], [math.tanh(0.5), sigmoid(-3.0), sigmoid(2.0)], rtol=1e-6)
    assert log.actions[0].dtype == np.float32


def test_car_racing_stops_on_the_21st_consecutive_negative_reward_as_truncation(car_racing_episode):
    steps, log = car_racing_episode
    rewards = np.array(log.rewards)
    negative_run = next((t for t in range(20, len(rewards)) if np.all(rewards[t - 20:t + 1] < 0)), None)
    assert negative_run is not None, rewards  # (the episode was not cut short before 21 negatives)
    assert len(steps) == negative_run + 1  # the 21st negative in a row is the last step
    *_, terminated, truncated, _ = steps[-1]
    assert truncated and not terminated
    assert not any(step[2] or step[3] for step in steps[:-1])
    assert not any(log.terminated)  # the environment itself never ended the episode


def test_car_racing_recipe_keeps_the_network_raw_and_normalises_hebbian_weights():
    env, recipe = make_env("CarRacing-v3")
    try:
        assert recipe.name == "CarRacing"
        net = network_spec(env, recipe)
        assert net.obs_shape == (3, 84, 84) and net.n_actions == 3 and not net.squash_out
        assert recipe.normalise_hebbian
    finally:
        env.close()


def test_recipe_is_chosen_by_family_not_by_exact_id():
    notices = []
    resolved = resolve_env_id("CarRacing-v0", notify=notices.append)
    with envs.quiet_output():
        retired = gym.make(resolved)
        renamed_id = "RenamedCarRacing-v0"
        gym.register(renamed_id, entry_point="gymnasium.envs.box2d.car_racing:CarRacing", max_episode_steps=1000)
        try:
            renamed = gym.make(renamed_id)
        finally:
            del gym.registry[renamed_id]
    assert resolved == "CarRacing-v3" and len(notices) == 1
    assert recipe_for(retired).name == "CarRacing"
    assert recipe_for(renamed).name == "CarRacing"  # an id the original's string test would miss
    assert recipe_for(gym.make("CartPole-v1")).name == "Gymnasium"
    retired.close()
    renamed.close()


# --- the pyBullet ant ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def ant_episode():
    """A real AntBulletEnv-v0 episode with a constant action (the ant collapses and lies still)."""
    env, log = logged("AntBulletEnv-v0")
    output = np.full(8, 0.5, dtype=np.float32)
    burn_in_actions = []

    class Watch(ConstantPolicy):
        def reset(self, params, rng):
            burn_in_actions.extend(log.actions)  # what the environment received before the first act
            return None

    rewards = []
    episode = rollout(env, Watch(output), np.zeros(0, dtype=np.float32), seed=4,
                      observer=lambda t, reward, state, info: rewards.append(reward))
    yield episode, log, burn_in_actions, env, rewards
    env.close()


def test_ant_burn_in_is_40_unrewarded_zero_actions_counted_in_steps(ant_episode):
    episode, log, burn_in_actions, _, rewards = ant_episode
    assert len(burn_in_actions) == 40
    assert all(np.array_equal(action, np.zeros(8)) for action in burn_in_actions)
    assert len(rewards) == len(log.actions) - 40  # the policy never saw the burn-in steps
    assert episode.steps == len(rewards) + 40


def test_ant_reward_is_the_progress_term(ant_episode):
    episode, log, _, _, rewards = ant_episode
    progress, full = np.array(log.progress[40:]), np.array(log.rewards[40:])
    np.testing.assert_array_equal(rewards, progress)  # rewards[1] of the unwrapped env, step by step
    assert not np.allclose(progress, full)  # the environment's own reward includes alive and costs
    assert episode.total_return == pytest.approx(progress.sum(), rel=1e-12, abs=1e-12)


def test_ant_termination_and_negative_streak_ignored_for_201_steps(ant_episode):
    episode, log, _, _, _ = ant_episode
    terminated = np.array(log.terminated[40:])
    progress = np.array(log.progress[40:])
    assert terminated[:201].sum() > 100  # the fallen ant reports termination, and is stepped on
    assert longest_run(progress[:201] < 0) > 31  # more than the patience, yet the episode went on
    assert len(progress) == 202 and terminated[201]  # ended by the 202nd policy step's termination
    assert episode.steps == 242


def test_ant_recipe_squashes_output_and_switches_off_hebbian_normalisation(ant_episode):
    env = ant_episode[3]
    recipe = recipe_for(env)
    assert recipe.name == "pyBullet ant"
    assert recipe.squash_output and network_spec(env, recipe).squash_out
    assert (recipe.stop_patience, recipe.stop_check_after, recipe.burn_in) == (30, 201, 40)
    problem = ProblemSpec(("AntBulletEnv-v0",), PolicySettings("hebbian")).build()
    try:
        assert problem.net.squash_out and problem.policy.normalise is False
        params = problem.policy.initial_params(np.random.default_rng(0)) * 10
        state = problem.policy.reset(params, np.random.default_rng(1))
        observation, _ = problem.envs[0].reset(seed=0)
        output, _ = problem.policy.act(params, state, observation)
        assert np.all(np.abs(output) <= 1.0)  # tanh is the network's own output activation
    finally:
        problem.close()
    other = ProblemSpec(("CartPole-v1",), PolicySettings("hebbian")).build()
    assert other.policy.normalise is True and not other.net.squash_out
    other.close()


# --- the wrappers on scripted environments -------------------------------------------------------


class ScriptedEnv(gym.Env):
    """Returns the scripted rewards in order, and terminates at the scripted steps."""

    def __init__(self, rewards, terminate_at=(), shape=(1,)):
        self.observation_space = spaces.Box(0.0, 255.0, shape, dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self.rewards, self.terminate_at = list(rewards), set(terminate_at)
        self.t = 0
        self.actions: list = []

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.zeros(self.observation_space.shape, np.float32), {}

    def step(self, action):
        self.actions.append(np.array(action))
        reward = self.rewards[self.t]
        self.t += 1
        return np.full(self.observation_space.shape, self.t, np.float32), reward, self.t in self.terminate_at, False, {}


def run_to_end(env: gym.Env, limit: int = 100) -> list[tuple]:
    env.reset(seed=0)
    steps = []
    while len(steps) < limit:
        steps.append(env.step(np.zeros(2, np.float32)))
        if steps[-1][2] or steps[-1][3]:
            break
    return steps


@pytest.mark.parametrize("rewards, patience, check_after, stop_step", [
    ([-1.0] * 10, 3, 0, 4),  # the 4th negative in a row exceeds a patience of 3
    ([-1.0, -1.0, 0.0, -1.0, -1.0, -1.0, -1.0, 5.0], 3, 0, 7),  # zero is not negative: the streak restarts
    ([-1.0, -1.0, 2.0, -0.1, -0.1, -0.1, -0.1], 2, 0, 6),
    ([-1.0] * 12, 2, 5, 8),  # steps 1-5 exempt; steps 6, 7, 8 are the streak
    ([-1.0] * 25 + [1.0] + [-1.0] * 25, 20, 0, 21),  # CarRacing: stop on the 21st
])
def test_negative_reward_stop_schedule(rewards, patience, check_after, stop_step):
    steps = run_to_end(NegativeRewardStop(ScriptedEnv(rewards), patience, check_after))
    assert len(steps) == stop_step
    assert steps[-1][3] and not steps[-1][2]  # a truncation, never a termination
    assert not any(step[3] for step in steps[:-1])


def test_negative_reward_stop_ignores_termination_only_before_check_after():
    env = NegativeRewardStop(ScriptedEnv([1.0] * 10, terminate_at={2, 3, 6}), patience=30, check_after=4)
    steps = run_to_end(env)
    assert len(steps) == 6  # the terminations at steps 2 and 3 are ignored, the one at step 6 is not
    assert steps[-1][2] and not steps[-1][3]


def test_negative_reward_stop_restarts_its_count_on_reset():
    env = NegativeRewardStop(ScriptedEnv([-1.0] * 40), patience=2, check_after=1)
    first = run_to_end(env)
    second = run_to_end(env)
    assert len(first) == len(second) == 4


def test_negative_reward_stop_validates_its_arguments():
    with pytest.raises(ValueError, match="-1"):
        NegativeRewardStop(ScriptedEnv([0.0]), patience=-1)
    with pytest.raises(ValueError, match="-3"):
        NegativeRewardStop(ScriptedEnv([0.0]), patience=1, check_after=-3)


def test_burn_in_steps_zeros_after_each_reset_and_returns_the_reset_observation():
    stub = ScriptedEnv([0.5] * 20)
    env = BurnIn(stub, 3)
    for _ in range(2):
        observation, info = env.reset(seed=0)
        assert info["burn_in_steps"] == 3 and stub.t == 3
        np.testing.assert_array_equal(observation, np.zeros(1))  # the reset's, not a burn-in step's
    assert len(stub.actions) == 6 and all(np.array_equal(action, np.zeros(2)) for action in stub.actions)
    with pytest.raises(ValueError, match="-2"):
        BurnIn(stub, -2)


def test_pixel_observation_keeps_the_original_transpose():
    frame = np.arange(84 * 84 * 3, dtype=np.int64).reshape(84, 84, 3) % 251  # every pixel distinct-ish

    class Frame(ScriptedEnv):
        def reset(self, *, seed=None, options=None):
            return frame.astype(np.uint8), {}

    env = PixelObservation(Frame([0.0], shape=(84, 84, 3)))
    observation, _ = env.reset()
    assert observation.shape == (3, 84, 84) and observation.dtype == np.float32
    # the original's np.swapaxes(obs, 0, 2): channel, then image column, then image row
    np.testing.assert_allclose(observation[1, 10, 70], frame[70, 10, 1] / 255.0, rtol=1e-6)
    np.testing.assert_allclose(observation, np.swapaxes(frame / 255.0, 0, 2), rtol=1e-6)
    with pytest.raises(ValueError, match="RGB"):
        PixelObservation(ScriptedEnv([0.0], shape=(84, 84)))


# --- custom recipes reach every process -------------------------------------------------------------


def test_a_custom_recipe_reaches_worker_processes_and_resumed_runs(tmp_path, monkeypatch):
    """Registered in this process by importing a module: worker processes, and a resume in a fresh
    process, must stop episodes the same way (same env steps, same theta as one process throughout),
    and config.json names the module."""
    import json
    import subprocess
    import sys

    import train_static
    from envs import recipes
    from es.files import load_dat, read_metrics
    from plugins import Registry

    monkeypatch.setattr(recipes, "RECIPES", Registry(None, recipes.RECIPES.values()))
    monkeypatch.setattr(recipes, "_CUSTOM_MODULES", [])
    monkeypatch.delitem(sys.modules, "tests.custom_recipe", raising=False)
    import tests.custom_recipe  # noqa: F401  (registers the recipe, in this process only)

    def train(folder, threads: str, generations: str) -> Path:
        assert train_static.main(["--environment", "tests.custom_env_module:TestCorridor-v0", "--popsize", "8",
                                  "--generations", generations, "--seed", "3", "--threads", threads,
                                  "--folder", str(folder)]) == 0
        (run_dir,) = folder.iterdir()
        return run_dir

    straight = train(tmp_path / "straight", "1", "3")
    split = train(tmp_path / "split", "2", "2")
    resumed = subprocess.run([sys.executable, "train_static.py", "--resume", str(split), "--generations", "3"],
                             cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert resumed.returncode == 0, resumed.stderr
    config = json.loads((split / "config.json").read_text())
    assert config["env"]["recipe_modules"] == ["tests.custom_recipe"]
    assert "NegativeRewardStop" in config["wrappers"]["tests.custom_env_module:TestCorridor-v0"]
    steps = [[int(row["env_steps"]) for row in read_metrics(run_dir / "metrics.csv")] for run_dir in (straight, split)]
    assert steps[0] == steps[1] and sum(steps[0]) < 3 * 9 * 20  # episodes stopped before the corridor's 20 steps
    assert load_dat(straight / "last.dat").tobytes() == load_dat(split / "last.dat").tobytes()
