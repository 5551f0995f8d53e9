"""Evaluation of a fixed parameter vector: the one function behind both evaluate scripts.

Each listed environment runs ``episodes`` episodes with seeds ``seed, seed + 1, ...`` through the
same rollout as training. The paper reports mean ± standard deviation over 100 rollouts
(Najarro & Risi 2020, as cited from its Table 1); the original code ran one random episode and left
the statistics to the user (docs/original.md, "Episodes"). The std is numpy's (population) std.

For ant environments (pyBullet ants, including the damaged ones, and MuJoCo Ant-v4/v5) each
episode also reports the **distance walked**: the straight-line distance, in metres, between the
torso's (x, y) position at the start of the policy steps (after the reset and any burn-in) and at
the end of the episode, and the **forward** displacement, its x component (signed: both ants are
rewarded for walking toward +x, so a negative value is walking backwards). The torso is
``robot.body_real_xyz`` in pyBullet (the torso link; the
progress reward uses ``body_xyz``, whose x and y average all body parts) and ``data.qpos[:2]``
(the free root joint) in MuJoCo. For pyBullet ants the return itself is the paper's "distance":
the sum of the progress reward, about 60.6 per metre walked toward the target at +x.

``trace_episode`` records the data of the paper's adaptation figure (``report.adaptation`` draws
it): per step, the reward (or, for ants, the distance from the start) and the Frobenius norm of each
dense layer's weights, which for a Hebbian network start random and settle within the first ~100
steps.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass, field

import gymnasium as gym
import numpy as np

from envs.problem import Problem
from envs.recipes import is_pybullet_ant
from envs.rollout import Episode, rollout

# --- the torso of ant environments --------------------------------------------------------------


def _pybullet_ant_torso(env) -> np.ndarray:
    return np.array(env.robot.body_real_xyz[:2], dtype=np.float64)


def _mujoco_ant_torso(env) -> np.ndarray:
    return np.array(env.data.qpos[:2], dtype=np.float64)


def _is_mujoco_ant(env) -> bool:
    if "mujoco" not in sys.modules:
        return False
    from gymnasium.envs.mujoco import ant_v4, ant_v5

    return isinstance(env, (ant_v4.AntEnv, ant_v5.AntEnv))


_TORSO: list[tuple[Callable[[gym.Env], bool], Callable[[gym.Env], np.ndarray]]] = [
    (is_pybullet_ant, _pybullet_ant_torso),  # the recipe's own test: damaged ants included
    (_is_mujoco_ant, _mujoco_ant_torso),
]


def torso_position(env: gym.Env) -> Callable[[gym.Env], np.ndarray] | None:
    """The function giving the torso's (x, y) of this (unwrapped) ant, or None if not an ant."""
    unwrapped = env.unwrapped
    return next((position for matches, position in _TORSO if matches(unwrapped)), None)


class TorsoTracker(gym.Wrapper):
    """Keeps the torso's (x, y) at the start of the policy steps and after the latest step."""

    def __init__(self, env: gym.Env, position: Callable[[gym.Env], np.ndarray]):
        super().__init__(env)
        self._position = position
        self.start = self.current = np.zeros(2)

    def reset(self, **kwargs):
        result = self.env.reset(**kwargs)  # burn-in, if any, runs inside: the start is after it
        self.start = self.current = self._position(self.env.unwrapped)
        return result

    def step(self, action):
        result = self.env.step(action)
        self.current = self._position(self.env.unwrapped)
        return result

    @property
    def distance(self) -> float:
        return float(np.linalg.norm(self.current - self.start))

    @property
    def forward(self) -> float:
        return float(self.current[0] - self.start[0])


def track_torso(env: gym.Env) -> TorsoTracker | None:
    position = torso_position(env)
    return TorsoTracker(env, position) if position is not None else None


# --- statistics over episodes -------------------------------------------------------------------


def _mean_std(values: list[float]) -> tuple[float | None, float | None]:
    if not values:
        return None, None
    return float(np.mean(values)), float(np.std(values))  # population std, as np.std


@dataclass
class EnvReport:
    env_id: str
    returns: list[float] = field(default_factory=list)
    steps: list[int] = field(default_factory=list)
    seeds: list[int] = field(default_factory=list)
    distances: list[float] = field(default_factory=list)  # metres; empty for non-ant environments
    forward: list[float] = field(default_factory=list)  # metres along +x; empty for non-ant environments

    @property
    def mean(self) -> float:
        return float(np.mean(self.returns))

    @property
    def std(self) -> float:
        return float(np.std(self.returns))

    def to_dict(self) -> dict:
        entry = dict(environment=self.env_id, episodes=len(self.returns), mean=self.mean, std=self.std,
                     returns=self.returns, steps=self.steps, seeds=self.seeds)
        if self.distances:
            distance_mean, distance_std = _mean_std(self.distances)
            forward_mean, forward_std = _mean_std(self.forward)
            entry.update(distance_mean=distance_mean, distance_std=distance_std, distances=self.distances,
                         forward_mean=forward_mean, forward_std=forward_std, forward=self.forward)
        return entry


class EpisodeError(RuntimeError):
    """An episode of the evaluation raised; names the environment and the episode's seed."""


def evaluate(problem: Problem, params: np.ndarray, episodes: int, seed: int,
             on_episode: Callable[[EnvReport], None] | None = None) -> list[EnvReport]:
    """``episodes`` episodes per environment; ``on_episode(report)`` after each (progress)."""
    reports = []
    for env_index, env_id in enumerate(problem.spec.env_ids):
        report = EnvReport(env_id)
        tracker = track_torso(problem.envs[env_index])
        env = tracker or problem.envs[env_index]
        for episode in range(episodes):
            try:
                result = rollout(env, problem.policy, params, seed + episode)
            except Exception as error:  # the environment (or a custom one's code) failed
                raise EpisodeError(f"{env_id} failed in the episode with seed {seed + episode}: "
                                   f"{type(error).__name__}: {error}") from error
            report.returns.append(result.total_return)
            report.steps.append(result.steps)
            report.seeds.append(seed + episode)
            if tracker is not None:
                report.distances.append(tracker.distance)
                report.forward.append(tracker.forward)
            if on_episode is not None:
                on_episode(report)
        reports.append(report)
    return reports


def format_table(reports: list[EnvReport]) -> str:
    """One row per environment: episodes, return, distance walked and forward displacement (ants),
    each as mean ± std."""
    width = max(len("environment"), *(len(report.env_id) for report in reports))
    lines = [f"{'environment':<{width}}  {'episodes':>8}  {'return':>20}  {'distance (m)':>14}  {'forward x (m)':>14}"]
    for report in reports:
        distance = forward = "-"
        if report.distances:
            distance = "{:.2f} ± {:.2f}".format(*_mean_std(report.distances))
            forward = "{:.2f} ± {:.2f}".format(*_mean_std(report.forward))
        lines.append(f"{report.env_id:<{width}}  {len(report.returns):>8}  "
                     f"{f'{report.mean:.2f} ± {report.std:.2f}':>20}  {distance:>14}  {forward:>14}")
    return "\n".join(lines)


# --- one episode, step by step: the adaptation figure -------------------------------------------


@dataclass
class Trace:
    env_id: str
    seed: int
    rewards: list[float] = field(default_factory=list)
    distances: list[float] = field(default_factory=list)  # metres from the start; ants only
    forward: list[float] = field(default_factory=list)  # metres along +x from the start; ants only
    layer_norms: list[list[float]] = field(default_factory=list)  # per step, one per dense layer
    layer_shapes: list[tuple[int, int]] = field(default_factory=list)
    episode: Episode | None = None


def trace_episode(problem: Problem, params: np.ndarray, seed: int, env_index: int = 0) -> Trace:
    """Run one episode and record, after every policy step, the reward, the distance walked (ants)
    and the Frobenius norm of each dense layer's current weights (plastic networks only)."""
    trace = Trace(problem.spec.env_ids[env_index], seed)
    tracker = track_torso(problem.envs[env_index])
    policy = problem.policy

    def observe(t: int, reward: float, state, info: dict) -> None:
        trace.rewards.append(reward)
        if tracker is not None:
            trace.distances.append(tracker.distance)
            trace.forward.append(tracker.forward)
        weights = policy.layer_weights(state)
        if weights is not None:  # static networks keep their weights: nothing to draw
            trace.layer_norms.append([float(np.linalg.norm(w)) for w in weights])

    trace.episode = rollout(tracker or problem.envs[env_index], policy, params, seed, observe)
    if trace.layer_norms:
        trace.layer_shapes = list(policy.net.layer_shapes)  # behind a front end (--reservoir), the head's
    return trace
