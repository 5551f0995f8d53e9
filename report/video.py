"""Videos of evaluation episodes: frames kept as the environment renders them, written as mp4."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np


class FrameRecorder(gym.Wrapper):
    """Keep ``env.render()`` frames (render_mode="rgb_array") of the episodes it sees."""

    def __init__(self, env: gym.Env, max_episodes: int = 1):
        super().__init__(env)
        self.frames: list[np.ndarray] = []
        self._episodes_left = max_episodes

    def reset(self, **kwargs):
        result = self.env.reset(**kwargs)
        self._recording = self._episodes_left > 0
        self._episodes_left -= 1
        self._capture()
        return result

    def step(self, action):
        result = self.env.step(action)
        self._capture()
        return result

    def _capture(self) -> None:
        if self._recording:
            frame = self.env.render()
            if frame is not None:
                self.frames.append(np.asarray(frame))


def record_first_episode(problem) -> FrameRecorder:
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
