"""Atari through ale-py: the ids, the family's pipeline, the FIRE reset, and Pong runs with small budgets.

- without ale-py an Atari id ends in one line naming the install (exit code 2): run always, with
  ale-py hidden from a subprocess;
- the FIRE reset (docs/original.md, "Episodes") on a scripted stub: presses after reset and after a lost life,
  their rewards dropped, a game that ends during the presses;
- with ale-py (skipped only where it is absent; CI installs it): the three Pong ids of the issue make
  the same pipeline; an agent step is 4 frames whatever the id (frames never skipped twice); FIRE is
  pressed in Breakout and Pong but not in Freeway; the Deterministic ids of gym 0.17;
- one generation on Pong (capped at 100 agent steps: ``tests.atari_short``) with the conv-LSTM and
  with the default CNN, static and Hebbian; the same parameters with 1 and 2 workers; evaluation
  of what was trained; an episode that does not depend on the episodes before it;
- ``--network lstm`` on CartPole and ``--network small`` on pixels refused in one line.
"""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

import evaluate_hebb
import evaluate_static
import train_hebb
import train_static
from envs.atari import FireReset, looks_like_atari
from es.files import load_dat, save_dat
from tests.extras import need

ROOT = Path(__file__).resolve().parent.parent
SHORT = "tests.atari_short:"


def run_in_process(main, *args) -> tuple[int, str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        code = main([str(arg) for arg in args])
    return code, out.getvalue()


def needs_ale():
    need("atari")
    import ale_py

    return ale_py


# --- ids and the missing extra ---------------------------------------------------------------------


@pytest.mark.parametrize("env_id, atari", [("PongNoFrameskip-v4", True), ("PongDeterministic-v4", True),
                                           ("ALE/Pong-v5", True), ("Breakout-v4", True), ("Pong-ram-v0", True),
                                           ("CartPole-v1", False), ("HalfCheetah-v5", False), ("Pongo-v1", False)])
def test_atari_ids_are_recognised_without_ale_py(env_id, atari):
    assert looks_like_atari(env_id) is atari


@pytest.mark.parametrize("script", ["train_static.py", "evaluate_static.py"])
def test_without_ale_py_an_atari_id_names_the_install(script, tmp_path):
    hide_ale = (f"import sys; sys.modules['ale_py'] = None; sys.argv = [{script!r}, '--environment', "
                f"'PongNoFrameskip-v4', '--path_weights', 'x.dat', '--folder', {str(tmp_path)!r}]; "
                f"import runpy; runpy.run_path({script!r}, run_name='__main__')")
    if script == "train_static.py":
        hide_ale = hide_ale.replace(", '--path_weights', 'x.dat'", "")
    else:  # a weight file that exists (evaluation reads it, and the config.json beside it, first)
        weights = tmp_path / "weights"
        weights.mkdir()
        save_dat(weights / "x.dat", np.zeros(3, np.float32))
        hide_ale = hide_ale.replace(f", '--folder', {str(tmp_path)!r}", "")
        hide_ale = hide_ale.replace("'x.dat'", repr(str(weights / "x.dat")))
    result = subprocess.run([sys.executable, "-c", hide_ale], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "PongNoFrameskip-v4" in lines[0] and "pip install -r requirements-atari.txt" in lines[0]
    assert sorted(path.name for path in tmp_path.iterdir()) == ([] if script == "train_static.py" else ["weights"])


# --- the FIRE reset on a stub ------------------------------------------------------------------------


class Lives(gym.Env):
    """A scripted game with FIRE: loses a life at step ``lose_at``, ends at step ``end_at``."""

    observation_space = spaces.Box(0, 1000, (1,), dtype=np.float32)
    action_space = spaces.Discrete(4)

    def __init__(self, lose_at=3, end_at=100):
        self.lose_at, self.end_at, self.actions = lose_at, end_at, []

    def get_action_meanings(self):
        return ["NOOP", "FIRE", "RIGHT", "LEFT"]

    def reset(self, *, seed=None, options=None):
        self.t, self.lives = 0, 3
        self.actions.append("reset")
        return np.array([0.0], np.float32), {"lives": self.lives}

    def step(self, action):
        self.t += 1
        self.actions.append(int(action))
        if self.t == self.lose_at:
            self.lives -= 1
        return np.array([self.t], np.float32), 1.0, self.t >= self.end_at, False, {"lives": self.lives}


def test_fire_reset_presses_fire_then_2_after_reset_and_after_a_lost_life():
    env = FireReset(Lives(lose_at=4))
    observation, info = env.reset()
    assert env.unwrapped.actions == ["reset", 1, 2] and observation[0] == 2 and info["lives"] == 3
    assert env.step(0)[:2] == (np.array([3.0]), 1.0)  # no life lost: no press
    observation, reward, terminated, truncated, info = env.step(3)  # step 4 loses a life
    assert env.unwrapped.actions[-3:] == [3, 1, 2]
    assert observation[0] == 6 and reward == 1.0 and info["lives"] == 2  # the presses' rewards are dropped
    env.step(0)
    assert env.unwrapped.actions[-1] == 0  # lives unchanged since: no press


def test_fire_reset_reports_a_game_that_ends_during_the_presses():
    env = FireReset(Lives(lose_at=4, end_at=5))
    env.reset()
    env.step(0)
    _, _, terminated, _, _ = env.step(0)
    assert terminated and env.unwrapped.actions[-2:] == [0, 1]  # the first press ended it: no second


def test_fire_reset_needs_fire():
    class NoFire(Lives):
        def get_action_meanings(self):
            return ["NOOP", "UP", "DOWN"]

    with pytest.raises(ValueError, match="FIRE"):
        FireReset(NoFire())


# --- the real games ------------------------------------------------------------------------------------


def frames_per_step(env_id, preprocessing):
    import envs

    env, _ = envs.make_env(envs.resolve_env_id(env_id), preprocessing=preprocessing)
    try:
        _, info = env.reset(seed=3)
        before = info["episode_frame_number"]
        _, _, _, _, info = env.step(np.zeros(env.action_space.shape[0], np.float32))
        return env, info["episode_frame_number"] - before
    finally:
        env.close()


@pytest.mark.parametrize("env_id", ["PongNoFrameskip-v4", "PongDeterministic-v4", "ALE/Pong-v5"])
def test_pong_ids_share_the_pipeline_and_step_4_frames(env_id):
    needs_ale()
    from envs.problem import wrapper_stack

    env, frames = frames_per_step(env_id, "default")
    assert frames == 4  # AtariPreprocessing skips only where the id does not
    assert wrapper_stack(env)[:4] == ["ArgmaxAction", "FrameStackObservation", "FireReset", "AtariPreprocessing"]
    assert env.observation_space.shape == (4, 84, 84)
    env, frames = frames_per_step(env_id, "pytorch-es")
    assert frames == 4
    assert wrapper_stack(env)[:5] == ["ArgmaxAction", "RunningNormalisation", "PytorchESFrame", "FireReset",
                                      "AtariPreprocessing"]
    assert env.observation_space.shape == (1, 42, 42)


def test_deterministic_ids_are_gym_0_17s():
    needs_ale()
    assert gym.spec("PongDeterministic-v4").kwargs["frameskip"] == 4
    assert gym.spec("PongDeterministic-v4").kwargs["repeat_action_probability"] == 0.0
    assert gym.spec("PongDeterministic-v0").kwargs["repeat_action_probability"] == 0.25
    assert gym.spec("SpaceInvadersDeterministic-v4").kwargs["frameskip"] == 3


def recorded_actions(env):
    """The actions the emulator receives (below every wrapper)."""
    base, actions, step = env.unwrapped, [], env.unwrapped.step

    def recording(action):
        actions.append(int(action))
        return step(action)

    base.step = recording
    return actions


@pytest.mark.parametrize("env_id, fire", [("BreakoutNoFrameskip-v4", True), ("PongNoFrameskip-v4", True),
                                          ("FreewayNoFrameskip-v4", False)])
def test_fire_is_pressed_where_the_game_has_it(env_id, fire):
    needs_ale()
    import envs
    from envs.problem import wrapper_stack

    env, _ = envs.make_env(env_id)
    assert ("FireReset" in wrapper_stack(env)) is fire
    actions = recorded_actions(env)
    env.reset(seed=1)
    # 1-30 no-op frames, then (with FIRE) FIRE and action 2 for 4 frames each
    if fire:
        assert actions[-8:] == [1] * 4 + [2] * 4 and set(actions[:-8]) == {0}
    else:
        assert set(actions) == {0}
    env.close()


def test_breakout_presses_fire_after_each_lost_life():
    needs_ale()
    import envs

    env, _ = envs.make_env("BreakoutNoFrameskip-v4")
    actions = recorded_actions(env)
    _, info = env.reset(seed=2)
    assert info["lives"] == 5
    for _ in range(2000):
        _, _, terminated, truncated, info = env.step(np.array([1.0, 0, 0, 0], np.float32))  # NOOP
        if terminated or truncated or info["lives"] < 5:
            break
    env.close()
    assert info["lives"] == 4 and actions[-8:] == [1] * 4 + [2] * 4


# --- training and evaluation on short Pong ------------------------------------------------------------


def train(main, folder, *argv):
    code, output = run_in_process(main, *argv, "--popsize", "2", "--generations", "1", "--seed", "5",
                                  "--folder", folder)
    assert code == 0, output[-3000:]
    (run_dir,) = Path(folder).iterdir()
    return run_dir, output


def test_pong_lstm_one_generation_with_1_and_2_workers_then_evaluate(tmp_path):
    needs_ale()
    runs = {}
    for threads in (1, 2):
        runs[threads], output = train(train_static.main, tmp_path / str(threads), "--environment",
                                      SHORT + "ShortPong-v5", "--network", "lstm", "--threads", threads)
        assert "parameters: 588710" in output
    assert load_dat(runs[1] / "last.dat").tobytes() == load_dat(runs[2] / "last.dat").tobytes()
    code, output = run_in_process(evaluate_static.main, "--environment", SHORT + "ShortPongDeterministic-v4",
                                  "--network", "lstm", "--path_weights", runs[1] / "last.dat", "--episodes", 2)
    assert code == 0 and "ShortPongDeterministic-v4" in output and "episode 2" in output, output


def test_pong_default_cnn_static_and_hebbian(tmp_path):
    needs_ale()
    static, output = train(train_static.main, tmp_path / "static", "--environment", SHORT + "ShortPongNoFrameskip-v4",
                           "--threads", 1)
    assert f"parameters: {6 * 4 * 9 + 1200 + 648 * 128 + 128 * 64 + 64 * 6}" in output
    hebbian, output = train(train_hebb.main, tmp_path / "hebbian", "--environment", SHORT + "ShortPong-v5",
                            "--threads", 1, "--hebb_rule", "A")
    assert load_dat(hebbian / "last_CNN_parameters.dat").size == 6 * 4 * 9 + 1200
    code, output = run_in_process(evaluate_hebb.main, "--environment", SHORT + "ShortPong-v5", "--hebb_rule", "A",
                                  "--path_hebb", hebbian / "last_coeffs.dat",
                                  "--path_coev", hebbian / "last_CNN_parameters.dat")
    assert code == 0, output


def test_an_episode_does_not_depend_on_the_episodes_before():
    """LSTM state and running normalisation restart at every reset: a reused environment and policy
    give the episode of fresh ones."""
    needs_ale()
    import tests.atari_short  # noqa: F401
    from envs import ProblemSpec, rollout
    from policies import PolicySettings

    spec = ProblemSpec(("ShortPongNoFrameskip-v4",), PolicySettings(network="lstm"), ("tests.atari_short",))
    used, fresh = spec.build(), spec.build()
    params = used.policy.initial_params(np.random.default_rng(8))
    rollout(used.envs[0], used.policy, params, 1)
    observations = {}
    for name, problem in (("used", used), ("fresh", fresh)):
        seen = observations[name] = []
        policy = problem.policy
        original_act = policy.act

        def act(params, state, obs, seen=seen, original_act=original_act):
            seen.append(obs.copy())
            return original_act(params, state, obs)

        policy.act = act
        rollout(problem.envs[0], policy, params, 2)
    assert len(observations["used"]) > 50
    np.testing.assert_array_equal(observations["used"], observations["fresh"])


@pytest.mark.parametrize("environment, network, words", [
    ("CartPole-v1", "lstm", "--network lstm is pytorch-es's conv-LSTM for images"),
    (SHORT + "ShortPong-v5", "small", "--network small is pytorch-es's MLP for state vectors")])
def test_networks_on_the_wrong_observations_are_refused_in_one_line(environment, network, words, tmp_path):
    if "Pong" in environment:
        needs_ale()
    code, output = run_in_process(train_static.main, "--environment", environment, "--network", network,
                                  "--folder", tmp_path)
    assert code == 2 and words in output and len(output.strip().splitlines()) == 1, output
    assert list(tmp_path.iterdir()) == []
