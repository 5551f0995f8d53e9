"""The fast CarRacing (issue 9) returns exactly what Gymnasium's does, and the project makes it by default.

Each scenario runs Gymnasium's class (``CarRacingStock-v3``) and ``FastCarRacing`` (``CarRacing-v3``)
side by side on the real environment, from the same seed with the same actions, and requires the
observations (and, where asked, the ``rgb_array`` frames) to be ``np.array_equal`` and the rewards,
``terminated``, ``truncated`` and ``info`` to be equal at every step, the zoom-in of the first second
included. Longer runs on other seeds and actions are in ``benchmarks/car_racing.py --identity``.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pygame
import pytest

import envs
from envs.car_racing import STOCK_ID, FastCarRacing, rotate_like_pygame
from gymnasium.envs.box2d.car_racing import CarRacing


def pair(render_mode: str | None = None, **kwargs) -> tuple[gym.Env, gym.Env]:
    with envs.quiet_output():
        return gym.make(STOCK_ID, render_mode=render_mode, **kwargs), gym.make("CarRacing-v3", render_mode=render_mode,
                                                                             **kwargs)


def assert_same_episode(seed: int, actions, render: bool = False, stock=None, fast=None, **kwargs) -> list:
    """Step both classes in lockstep; the stock transitions, for checks on what the episode did."""
    if stock is None:
        stock, fast = pair("rgb_array" if render else None, **kwargs)
    stock_obs, stock_info = stock.reset(seed=seed)
    fast_obs, fast_info = fast.reset(seed=seed)
    assert np.array_equal(stock_obs, fast_obs) and stock_info == fast_info
    transitions = []
    for step, action in enumerate(actions):
        expected, got = stock.step(action), fast.step(action)
        assert np.array_equal(expected[0], got[0]), f"seed {seed}: observations differ at step {step}"
        assert expected[1:] == got[1:], f"seed {seed}, step {step}: {expected[1:]} != {got[1:]}"
        if render:
            assert np.array_equal(stock.render(), fast.render()), f"seed {seed}: frames differ at step {step}"
        transitions.append(expected[1:])
        if expected[2] or expected[3]:
            break
    return transitions


def constant(action, steps: int) -> list[np.ndarray]:
    return [np.array(action, dtype=np.float32)] * steps


def test_leaving_the_playfield_ends_with_minus_100():
    # gas 1.0 spins the rear wheels on the starting grass (the car stays on the playfield for 1000
    # steps); 0.5 drives it straight out in about 270 steps
    transitions = assert_same_episode(11, constant([0.0, 1.0, 0.0], 30) + constant([0.0, 0.5, 0.0], 400))
    reward, terminated, truncated, info = transitions[-1]
    assert reward == -100 and terminated and not truncated and info == {"lap_finished": False}


def test_hard_turns():
    turns = [np.array([1.0 if (step // 40) % 2 else -1.0, 0.4, 0.0], dtype=np.float32) for step in range(250)]
    transitions = assert_same_episode(12, turns)
    assert len(transitions) == 250 and any(reward > 0 for reward, *_ in transitions)  # it visited tiles


def test_braking():
    cycle = constant([0.0, 1.0, 0.0], 30) + constant([0.2, 0.0, 1.0], 20)
    assert len(assert_same_episode(13, cycle * 4)) == 200


def test_random_actions_then_a_second_reset_of_the_same_instance():
    rng = np.random.default_rng(14)
    actions = rng.uniform([-1, 0, 0], [1, 1, 1], size=(250, 3)).astype(np.float32)
    stock, fast = pair()
    assert len(assert_same_episode(14, actions, stock=stock, fast=fast)) == 250
    assert len(assert_same_episode(15, actions[:100], stock=stock, fast=fast)) == 100


def test_rgb_array_frames_skid_marks_included():
    rng = np.random.default_rng(16)
    actions = [np.array([rng.uniform(-1, 1), 1.0, 0.0 if step < 60 else 0.9], dtype=np.float32) for step in range(110)]
    assert len(assert_same_episode(16, actions, render=True)) == 110


def test_domain_randomisation_and_discrete_actions():
    rng = np.random.default_rng(17)
    stock, fast = pair(domain_randomize=True)
    assert_same_episode(17, rng.uniform([-1, 0, 0], [1, 1, 1], size=(60, 3)).astype(np.float32), stock=stock, fast=fast)
    stock.reset(seed=18, options={"randomize": False}), fast.reset(seed=18, options={"randomize": False})
    assert_same_episode(18, constant([0.0, 0.5, 0.0], 40), stock=stock, fast=fast)
    assert_same_episode(19, rng.integers(0, 5, size=60).tolist(), continuous=False)


def test_rotation_is_pygames_bit_for_bit():
    rng = np.random.default_rng(20)
    points = rng.normal(0, 400, size=(64, 2))
    quarter_turns = [k * math.pi / 2 for k in range(-8, 9)]
    angles = [*rng.uniform(-20, 20, size=40), *quarter_turns, *(a + 5e-7 for a in quarter_turns), 2 * math.pi - 1e-12]
    for angle in angles:
        expected = [tuple(pygame.math.Vector2(tuple(point)).rotate_rad(angle)) for point in points.tolist()]
        assert rotate_like_pygame(points, angle).tolist() == [list(point) for point in expected], angle


def test_project_ids_make_the_fast_class_and_the_stock_id_gymnasiums():
    assert type(gym.make("CarRacing-v3").unwrapped) is FastCarRacing
    assert type(gym.make(STOCK_ID).unwrapped) is CarRacing
    assert gym.spec(STOCK_ID).max_episode_steps == gym.spec("CarRacing-v3").max_episode_steps == 1000
    for env_id, cls in (("CarRacing-v0", FastCarRacing), ("CarRacing-v3", FastCarRacing), (STOCK_ID, CarRacing)):
        env, recipe = envs.make_env(envs.resolve_env_id(env_id, notify=lambda _: None))
        try:
            assert type(env.unwrapped) is cls and recipe.name == "CarRacing"  # action squashing, early stop
        finally:
            env.close()


@pytest.mark.parametrize("env_id", ["CarRacing-v3", STOCK_ID])
def test_render_mode_for_videos(env_id):
    env, _ = envs.make_env(env_id, render_mode="rgb_array")
    try:
        assert env.render().shape == (400, 600, 3)
    finally:
        env.close()
