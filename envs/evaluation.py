"""Evaluation of a fixed parameter vector: the one function behind both evaluate scripts.

Each listed environment runs ``episodes`` episodes with seeds ``seed, seed + 1, ...`` through the
same rollout as training.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from envs.problem import Problem
from envs.rollout import rollout
from envs.wrappers import FrameRecorder


@dataclass
class EnvReport:
    env_id: str
    returns: list[float] = field(default_factory=list)
    steps: list[int] = field(default_factory=list)

    @property
    def mean(self) -> float:
        return float(np.mean(self.returns))

    @property
    def std(self) -> float:
        return float(np.std(self.returns))


def evaluate(problem: Problem, params: np.ndarray, episodes: int, seed: int,
             on_episode=None) -> list[EnvReport]:
    reports = []
    for env_index, env_id in enumerate(problem.spec.env_ids):
        report = EnvReport(env_id)
        for episode in range(episodes):
            result = rollout(problem.envs[env_index], problem.policy, params, seed + episode)
            report.returns.append(result.total_return)
            report.steps.append(result.steps)
            if on_episode is not None:
                on_episode(env_id, episode, seed + episode, result)
        reports.append(report)
    return reports


def record_first_episode(problem: Problem) -> FrameRecorder:
    """Wrap the first environment so that its first episode's frames are kept."""
    recorder = FrameRecorder(problem.envs[0], max_episodes=1)
    problem.envs[0] = recorder
    return recorder


def write_video(path: str | Path, frames: list[np.ndarray], fps: int = 30) -> None:
    """An mp4 (H.264) of RGB frames; odd sizes are padded to even ones, as the codec needs."""
    import imageio.v2 as imageio

    if not frames:
        raise ValueError("no frames were rendered; the environment may not support rgb_array rendering")
    height, width = frames[0].shape[:2]
    pad = ((0, height % 2), (0, width % 2), (0, 0))
    with imageio.get_writer(str(path), fps=fps, macro_block_size=1, codec="libx264",
                            pixelformat="yuv420p") as writer:
        for frame in frames:
            writer.append_data(np.pad(frame[..., :3], pad))
