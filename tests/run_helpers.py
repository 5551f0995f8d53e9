"""Helpers for the tests that run training as a real process and watch it (resume, faults, progress)."""

from __future__ import annotations

import json
import os
import queue
import shlex
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from envs import ProblemSpec
from es.files import load_dat, read_metrics
from es.loop import Trainer
from es.runfolder import RunFolder
from es.settings import ESSettings, RunSettings

ROOT = Path(__file__).resolve().parent.parent
WALL_CLOCK_COLUMNS = ("seconds", "total_seconds")


class Training:
    """``train_static.py`` in its own process group, its output read line by line in the background.

    Its own session lets a test send SIGINT to the whole group, as a terminal's Ctrl-C does.
    """

    def __init__(self, *argv: str, env: dict | None = None):
        self.process = subprocess.Popen(
            [sys.executable, str(ROOT / "train_static.py"), *argv], cwd=ROOT, text=True,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})})
        self.stdout: list[str] = []
        self.stderr: list[str] = []
        self._lines: queue.Queue = queue.Queue()
        self._readers = [self._read(self.process.stdout, self.stdout), self._read(self.process.stderr, self.stderr)]

    def _read(self, stream, lines: list[str]) -> threading.Thread:
        def pump():
            for line in stream:
                lines.append(line.rstrip("\n"))
                self._lines.put(line)
        thread = threading.Thread(target=pump, daemon=True)
        thread.start()
        return thread

    def wait_for(self, text: str, timeout: float = 60) -> None:
        """Block until a line of stdout or stderr contains ``text``."""
        deadline = time.monotonic() + timeout
        while not any(text in line for line in self.stdout + self.stderr):
            try:
                self._lines.get(timeout=max(0.01, deadline - time.monotonic()))
            except queue.Empty:
                pass
            if time.monotonic() > deadline or (self.process.poll() is not None and self._lines.empty()
                                               and not any(reader.is_alive() for reader in self._readers)):
                raise AssertionError(f"no line with {text!r}; stdout: {self.stdout}, stderr: {self.stderr}")

    def finish(self, timeout: float = 60) -> int:
        self.process.wait(timeout=timeout)
        for reader in self._readers:
            reader.join(timeout=5)
        return self.process.returncode

    def kill(self) -> None:
        """Clean-up: end whatever is left of the process group."""
        try:
            os.killpg(self.process.pid, 9)
        except ProcessLookupError:
            pass
        self.process.wait()


def hint(script: str, *words) -> str:
    """A command as the scripts print it: this interpreter, the script by its absolute path, shell-quoted
    words."""
    return shlex.join([sys.executable, str(ROOT / script), *map(str, words)])


def _parent_and_state(pid: int) -> tuple[int, str] | None:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    state, parent = stat.rsplit(")", 1)[1].split()[:2]  # the name in parentheses may hold spaces
    return int(parent), state


def descendants(pid: int) -> set[int]:
    """Every process below ``pid`` (Linux /proc): forkserver, resource tracker, workers."""
    parents = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and (found := _parent_and_state(int(entry.name))) is not None:
            parents[int(entry.name)] = found[0]
    below, frontier = set(), {pid}
    while frontier:
        frontier = {child for child, parent in parents.items() if parent in frontier} - below
        below |= frontier
    return below


def still_running(pids: set[int], timeout: float = 10) -> set[int]:
    """The pids that are still running (zombies count as gone) after waiting up to ``timeout``."""
    deadline = time.monotonic() + timeout
    while True:
        running = {pid for pid in pids if (found := _parent_and_state(pid)) is not None and found[1] != "Z"}
        if not running or time.monotonic() > deadline:
            return running
        time.sleep(0.1)


def only_run(folder: Path) -> Path:
    (run_dir,) = [path for path in Path(folder).iterdir() if path.is_dir()]
    return run_dir


def comparable_metrics(run_dir: Path) -> list[dict]:
    """metrics.csv without the wall-clock columns."""
    return [{key: value for key, value in row.items() if key not in WALL_CLOCK_COLUMNS}
            for row in read_metrics(run_dir / "metrics.csv")]


def assert_same_checkpoint_and_metrics(first: Path, second: Path) -> None:
    """The checkpoints bit for bit but for wall clock and where the runs were made (the record of their
    settings holds --folder), and the same metrics but for wall clock."""
    with np.load(first / "checkpoint.npz") as one, np.load(second / "checkpoint.npz") as other:
        assert sorted(one.files) == sorted(other.files)
        for key in one.files:
            if key == "settings":
                assert recorded_settings(one[key]) == recorded_settings(other[key])
            elif key not in ("total_seconds", "settings_digest"):
                assert one[key].tobytes() == other[key].tobytes(), key
    assert comparable_metrics(first) == comparable_metrics(second)


def recorded_settings(record: np.ndarray) -> dict:
    """A checkpoint's record of the settings it was written under, but the folder the run was made in."""
    settings = json.loads(str(record))
    settings.pop("folder")
    return settings


def assert_same_run(first: Path, second: Path) -> None:
    """Bit-for-bit the same weights, checkpoint and fitness log; the same metrics but for wall clock."""
    for name in ("last.dat", "best.dat"):
        assert load_dat(first / name).tobytes() == load_dat(second / name).tobytes(), name
    assert_same_checkpoint_and_metrics(first, second)
    (fitness_one,), (fitness_other,) = first.glob("Fitness_values_*.npy"), second.glob("Fitness_values_*.npy")
    assert np.load(fitness_one).tobytes() == np.load(fitness_other).tobytes()


def small_trainer(folder: Path, popsize: int = 4, generations: int = 1, log=lambda line: None,
                  env_id: str = "CartPole-v1") -> Trainer:
    """A static trainer on one environment, everything in this process, writing into ``folder``."""
    spec = ProblemSpec((env_id,))
    return Trainer.start(ESSettings(popsize=popsize), RunSettings(generations=generations, threads=1), spec.build(),
                         spec.build, spec.env_ids, RunFolder(Path(folder)), env_id, log=log)
