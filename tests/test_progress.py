"""Observability: the live progress line on a terminal, plain lines elsewhere, and the plots."""

from __future__ import annotations

import io
import math
import os
import pty
import sys
import threading
import time

import numpy as np
import pytest

import plot_run
import train_static
from es import files
from es.runfolder import SaveError
from report import plots
from report.log import FitnessPlot
from report.progress import LiveDisplay, QuietDisplay, display_for, estimate
from tests.run_helpers import Training, hint, only_run

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


class FakeTerminal(io.StringIO):
    def isatty(self) -> bool:
        return True


# --- the live line ---------------------------------------------------------------------------------


def test_estimate_projects_this_generation_and_the_rest_of_the_run():
    assert all(math.isnan(value) for value in estimate(0, 10, 1.0, 5, []))
    assert estimate(2, 10, 4.0, 3, []) == (16.0, 16.0 + 3 * 20.0)  # no history: this one's projection
    assert estimate(5, 10, 5.0, 2, [8.0, 12.0]) == (5.0, 5.0 + 2 * 10.0)  # recent generations' mean


def test_only_a_terminal_gets_a_live_display():
    assert isinstance(display_for(FakeTerminal()), LiveDisplay)
    quiet = display_for(io.StringIO())
    assert isinstance(quiet, QuietDisplay)
    with quiet.generation(1, 10, 0) as progress:
        assert progress is None


def test_the_live_line_shows_episodes_speed_and_both_etas():
    terminal = FakeTerminal()
    display = LiveDisplay(terminal)
    with display.generation(3, 3, 10) as progress:
        for _ in range(3):
            time.sleep(0.12)  # tqdm redraws at most every 0.1 s
            progress(1, 50)
    shown = terminal.getvalue()
    assert "generation 3 |" in shown and "3/3 episodes, " in shown
    assert "steps/s | generation ETA 00:00 | run ETA 00:0" in shown
    assert shown.endswith("\r")  # the bar is cleared when the generation ends: the log line takes its place
    assert len(display.recent) == 1


def _read_all(descriptor: int, into: list[bytes]) -> None:
    while True:
        try:
            chunk = os.read(descriptor, 4096)
        except OSError:  # the other end is closed
            return
        if not chunk:
            return
        into.append(chunk)


def test_a_run_on_a_terminal_draws_the_bar_between_its_lines(tmp_path, monkeypatch):
    leader, follower = pty.openpty()
    received: list[bytes] = []
    reader = threading.Thread(target=_read_all, args=(leader, received), daemon=True)
    reader.start()
    with open(follower, "w", closefd=True) as terminal:
        monkeypatch.setattr(sys, "stdout", terminal)
        assert train_static.main(["--environment", "CartPole-v1", "--popsize", "8", "--seed", "1", "--threads", "1",
                                  "--generations", "2", "--folder", str(tmp_path)]) == 0
    reader.join(timeout=5)
    os.close(leader)
    shown = b"".join(received).decode()
    assert "\rgeneration 1 |" in shown and "\rgeneration 2 |" in shown and " episodes" in shown
    assert "iter 1 | " in shown and "iter 2 | " in shown


# --- plain output, and the run's picture --------------------------------------------------------


@pytest.fixture(scope="module")
def piped_run(tmp_path_factory):
    """A 3-generation run with worker processes and stdout on a pipe, as under CI or nohup."""
    folder = tmp_path_factory.mktemp("piped")
    training = Training("--environment", "CartPole-v1", "--popsize", "8", "--seed", "1", "--threads", "2",
                        "--generations", "3", "--folder", str(folder))
    try:
        assert training.finish(timeout=120) == 0, training.stderr
    finally:
        training.kill()
    return only_run(folder), training.stdout


def test_output_that_is_not_a_terminal_is_one_line_per_generation(piped_run):
    run_dir, lines = piped_run
    assert lines[0].startswith(f"run folder: {run_dir} | ")
    assert [line.split(" | ")[0] for line in lines[1:-1]] == ["iter 1", "iter 2", "iter 3"]
    evaluate = hint("evaluate_static.py", "--path_weights", run_dir / "last.dat", "--episodes", 10)
    assert lines[-1] == f"done; evaluate with: {evaluate}"
    assert not any("\r" in line for line in lines)


def test_the_run_draws_its_learning_curve(piped_run):
    run_dir, _ = piped_run
    assert (run_dir / "fitness.png").read_bytes().startswith(PNG_SIGNATURE)
    assert not list(run_dir.glob(".*.tmp"))


class DrawnFolder:
    """A run folder that counts what is drawn into it; ``full`` makes every write fail as a full disk does."""

    name = "run"

    def __init__(self):
        self.drawn, self.full = [], False

    def write(self, write, name, rows, title):
        if self.full:
            raise SaveError(f"cannot write {name}: No space left on device")
        self.drawn.append([row["generation"] for row in rows])


def test_the_learning_curve_is_drawn_at_most_every_redraw_seconds_and_at_the_end():
    """A save draws once redraw_seconds have passed since the last drawing (or the start); the run's end draws
    every row saved; nothing is drawn twice, and a full disk at the end does not raise."""
    now = [0.0]
    plot, folder = FitnessPlot(redraw_seconds=30.0, clock=lambda: now[0]), DrawnFolder()
    rows = []
    for generation, at in enumerate((5.0, 10.0, 31.0, 40.0, 45.0), 1):
        now[0] = at
        rows.append({"generation": generation})
        plot.saved(folder, rows)
    assert folder.drawn == [[1, 2, 3]]  # at 31 s: 30 s after the start
    plot.finished(folder)
    assert folder.drawn == [[1, 2, 3], [1, 2, 3, 4, 5]]
    plot.close()
    assert len(folder.drawn) == 2  # nothing new to draw
    rows.append({"generation": 6})
    plot.saved(folder, rows)
    folder.full = True
    plot.close()  # an interrupted run on a full disk: its data are saved, no traceback for the picture
    with pytest.raises(SaveError):
        plot.finished(folder)  # a finished run says the picture could not be written


def test_curves_keep_the_best_so_far_across_nan_generations():
    rows = [{"generation": g, "fitness_mean": mean, "fitness_max": best, "fitness_min": 0, "center_return": 0}
            for g, mean, best in [(1, 0.5, 1.0), (2, "nan", "nan"), (3, 2.0, 3.0), (4, 1.0, 2.0)]]
    data = plots.curves(rows)
    assert data["best"].tolist() == [1.0, 1.0, 3.0, 3.0]
    assert np.isnan(data["mean"][1]) and data["generation"].tolist() == [1, 2, 3, 4]


def test_plot_run_overlays_several_runs(piped_run, tmp_path, capsys):
    run_dir, _ = piped_run
    other = tmp_path / "other_run"
    other.mkdir()
    rows = files.read_metrics(run_dir / "metrics.csv")
    files.write_metrics(other / "metrics.csv", [dict(row, fitness_mean=float(row["fitness_mean"]) / 2) for row in rows])
    output = tmp_path / "compare.png"
    assert plot_run.main([str(run_dir), str(other), "-o", str(output)]) == 0
    assert output.read_bytes().startswith(PNG_SIGNATURE)
    assert capsys.readouterr().out.strip() == f"wrote {output} (2 runs)"


def test_plot_run_refuses_a_folder_without_metrics_in_one_line(tmp_path, capsys):
    assert plot_run.main([str(tmp_path), "-o", str(tmp_path / "x.png")]) == 2
    assert capsys.readouterr().err.strip() == (f"plot_run.py: error: {tmp_path}: no metrics.csv here "
                                               "(not a run folder, or no generation finished yet)")
    assert not (tmp_path / "x.png").exists()
