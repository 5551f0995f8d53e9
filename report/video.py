"""Videos of evaluation episodes, written frame by frame as the environment renders them, or strips of frames.

The frames go to the file as they come (an H.264 mp4 through imageio's ffmpeg), so a long episode
never accumulates in memory; they go to a temporary file, renamed over the target when it closes;
odd frame sizes are padded to even ones, as the codec needs. While a
terminal watches, a progress line counts the frames written.

A ``.png`` path gets a strip instead: every ``STRIP_EVERY``-th frame of the episode (the first and
then one every few seconds of play), at half size, ``STRIP_COLUMNS`` to a row, in one picture for a
page (only those frames are rendered and kept; rendering reads the environment's state, never changes
it, so the frames left out change nothing).
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import gymnasium as gym
import numpy as np

from es.files import _FILE_MODE

VIDEO_SUFFIXES = (".mp4", ".mkv", ".mov", ".avi", ".png")  # containers ffmpeg writes H.264 into; a strip
STRIP_EVERY, STRIP_COLUMNS = 100, 5


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
        self._strip: list[np.ndarray] | None = [] if self.path.suffix.lower() == ".png" else None

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
        if self._strip is not None and self.frames_written % STRIP_EVERY:
            self.frames_written += 1  # a frame the strip leaves out is not rendered (a pyBullet frame costs ms)
            return
        frame = self.env.render()
        if frame is None:
            return
        frame = np.asarray(frame)[..., :3]
        if self._strip is not None:
            self._strip.append(np.ascontiguousarray(frame[::2, ::2]))
            self.frames_written += 1
            return
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
        if self._strip:
            write_strip(self.path, self._strip)
            self._strip = []
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


def write_strip(path: Path, frames: list[np.ndarray]) -> None:
    """``frames`` (equal shapes) in rows of ``STRIP_COLUMNS``, the last row's gaps white, as a PNG."""
    import io

    from PIL import Image

    from es.files import atomic_write_bytes

    height, width, _ = frames[0].shape
    rows = -(-len(frames) // STRIP_COLUMNS)
    columns = min(len(frames), STRIP_COLUMNS)
    picture = np.full((rows * height, columns * width, 3), 255, dtype=np.uint8)
    for index, frame in enumerate(frames):
        row, column = divmod(index, STRIP_COLUMNS)
        picture[row * height:(row + 1) * height, column * width:(column + 1) * width] = frame
    buffer = io.BytesIO()
    Image.fromarray(picture).save(buffer, format="PNG")
    atomic_write_bytes(path, buffer.getvalue())


def record_first_episode(problem, path: str | Path) -> VideoRecorder:
    """Wrap the first environment so that its first episode's frames are written to ``path``."""
    env = problem.envs[0]
    recorder = VideoRecorder(env, path, int(env.metadata.get("render_fps") or 30))
    problem.envs[0] = recorder
    return recorder
