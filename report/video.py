"""Videos of evaluation episodes, written frame by frame as the environment renders them.

The frames go to the file as they come (an H.264 mp4 through imageio's ffmpeg), so a long episode
never accumulates in memory; they go to a temporary file, renamed over the target when it closes;
odd frame sizes are padded to even ones, as the codec needs. While a
terminal watches, a progress line counts the frames written.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import gymnasium as gym
import numpy as np

from es.files import _FILE_MODE

VIDEO_SUFFIXES = (".mp4", ".mkv", ".mov", ".avi")  # containers ffmpeg writes H.264 into


class VideoRecorder(gym.Wrapper):
    """Writes the ``env.render()`` frames (render_mode="rgb_array") of the first episode to ``path``."""

    def __init__(self, env: gym.Env, path: str | Path, fps: int = 30):
        super().__init__(env)
        self.path, self.fps = Path(path), fps
        self.frames_written = 0
        self._writer = None
        self._progress = None
        self._recording = False
        self._recorded = False

    def reset(self, **kwargs):
        result = self.env.reset(**kwargs)
        self._recording = not self._recorded
        self._recorded = True
        self._capture()
        return result

    def step(self, action):
        result = self.env.step(action)
        self._capture()
        if result[2] or result[3]:
            self._recording = False
            self.finish()
        return result

    def _capture(self) -> None:
        if not self._recording:
            return
        frame = self.env.render()
        if frame is None:
            return
        frame = np.asarray(frame)[..., :3]
        if self._writer is None:
            self._open(frame.shape)
        self._writer.append_data(np.pad(frame, self._pad))
        self.frames_written += 1
        if self._progress is not None:
            self._progress.update(1)

    def _open(self, shape: tuple[int, ...]) -> None:
        import imageio.v2 as imageio

        height, width = shape[:2]
        self._pad = ((0, height % 2), (0, width % 2), (0, 0))
        # frames go to a temporary file beside the target (ending in the same suffix: ffmpeg picks the
        # container by it), renamed over the target once closed
        descriptor, temporary = tempfile.mkstemp(dir=self.path.parent, prefix=f".{self.path.name}.",
                                                 suffix=f".tmp{self.path.suffix}")
        os.close(descriptor)
        self._temporary = Path(temporary)
        self._writer = imageio.get_writer(temporary, fps=self.fps, macro_block_size=1, codec="libx264",
                                          pixelformat="yuv420p")
        if sys.stderr.isatty():
            from tqdm import tqdm

            self._progress = tqdm(desc=f"recording {self.path.name}", unit=" frames", file=sys.stderr, leave=False)

    def finish(self) -> None:
        """Close the file (also after an interrupted episode: what was recorded is kept)."""
        if self._progress is not None:
            self._progress.close()
            self._progress = None
        if self._writer is not None:
            self._writer.close()
            self._writer = None
            os.chmod(self._temporary, _FILE_MODE)
            os.replace(self._temporary, self.path)

    def close(self) -> None:
        self.finish()
        super().close()


def record_first_episode(problem, path: str | Path) -> VideoRecorder:
    """Wrap the first environment so that its first episode's frames are written to ``path``."""
    env = problem.envs[0]
    recorder = VideoRecorder(env, path, int(env.metadata.get("render_fps") or 30))
    problem.envs[0] = recorder
    return recorder
