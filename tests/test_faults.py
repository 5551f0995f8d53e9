"""Faults: failing environments, dying workers, NaN returns, Ctrl-C twice, unwritable and full disks.

The failing environment is tests/failing_env.py, made through Gymnasium's ``module:EnvId`` form and
steered by environment variables; runs with worker processes are real ``train_static.py`` processes.
"""

from __future__ import annotations

import errno
import os
import re
import signal
import time

import numpy as np
import pytest

import train_static
from es import files
from es.backends import Results
from es.interrupts import Interrupts
from es.runfolder import read_checkpoint
from es.shaping import rank_std
from report.log import generation_line
from tests.run_helpers import Training, descendants, hint, only_run, small_trainer, still_running

FAILING_ENV = "tests.failing_env:FailingEnv-v0"
SMALL = ("--environment", FAILING_ENV, "--popsize", "4", "--seed", "2")


def train(*argv: str) -> int:
    return train_static.main(list(argv))


def failing(how: str, step: int = 3, once_file=None) -> dict:
    settings = {"FAILING_ENV_HOW": how, "FAILING_ENV_STEP": str(step)}
    return settings | ({"FAILING_ENV_ONCE": str(once_file)} if once_file else {})


def run_with_workers(tmp_path, settings: dict, generations: int = 1) -> Training:
    training = Training(*SMALL, "--threads", "2", "--generations", str(generations), "--folder", str(tmp_path),
                        env=settings)
    try:
        training.finish(timeout=120)
    finally:
        training.kill()
    return training


# --- an episode that raises, a worker that dies -------------------------------------------------


def set_failing(monkeypatch, how: str, step: int = 3, once_file=None) -> None:
    """For runs in this process (--threads 1): the environment reads these when it is made."""
    for name, value in failing(how, step, once_file).items():
        monkeypatch.setenv(name, value)


def retried_warning(lines: list[str], reported: str) -> None:
    warnings = [line for line in lines if line.startswith("warning:")]
    assert len(warnings) == 1, lines
    assert re.fullmatch(rf"warning: {FAILING_ENV} failed once for member \d+ \(episode seed \d+\): "
                        rf"{re.escape(reported)}; retried", warnings[0])


def test_an_episode_that_raises_once_is_retried_and_reported(tmp_path, monkeypatch, capsys):
    set_failing(monkeypatch, "raise", once_file=tmp_path / "failed-once")
    assert train(*SMALL, "--threads", "1", "--generations", "1", "--folder", str(tmp_path / "run")) == 0
    lines = capsys.readouterr().out.splitlines()
    retried_warning(lines, "RuntimeError: FailingEnv: failure at step 3")
    assert lines[-2].startswith("iter 1 | ") and lines[-1].startswith("done; evaluate with: ")


def test_a_worker_that_dies_once_is_replaced_and_its_episode_retried(tmp_path):
    training = run_with_workers(tmp_path / "run", failing("exit", once_file=tmp_path / "failed-once"))
    assert training.process.returncode == 0, training.stderr
    retried_warning(training.stdout, "worker process died (exit code 3)")
    assert training.stdout[-2].startswith("iter 1 | ")


def test_a_worker_that_crashes_twice_stops_the_run_after_a_checkpoint(tmp_path):
    training = run_with_workers(tmp_path, failing("segfault"))
    assert training.process.returncode == 1
    run_dir = only_run(tmp_path)
    error = next(line for line in training.stdout if line.startswith("error:"))
    assert re.fullmatch(rf"error: {FAILING_ENV} failed twice for member \d+ \(episode seed \d+\): "
                        r"worker process died \(killed by SIG(SEGV|ABRT)\)", error)  # ABRT: pygame's handler
    assert training.stdout[-1] == (f"stopped; the checkpoint holds generation 0; "
                                   f"resume with: {hint('train_static.py', '--resume', run_dir)}")
    with np.load(run_dir / "checkpoint.npz") as saved:
        assert int(saved["generation"]) == 0


def test_an_episode_that_always_raises_stops_the_run_naming_env_member_and_error(tmp_path, monkeypatch, capsys):
    set_failing(monkeypatch, "raise")
    assert train(*SMALL, "--threads", "1", "--generations", "2", "--folder", str(tmp_path)) == 1
    out = capsys.readouterr().out
    assert re.search(rf"^error: {FAILING_ENV} failed twice for member 0 \(episode seed \d+\): "
                     r"RuntimeError: FailingEnv: failure at step 3$", out, re.MULTILINE)
    assert (only_run(tmp_path) / "checkpoint.npz").is_file()


# --- NaN returns -----------------------------------------------------------------------------------


class _ScriptedReturns:
    """An evaluator whose members return the given values (the centre returns 0)."""

    workers = 1

    def __init__(self, member_returns):
        self.member_returns = np.array(member_returns, dtype=np.float64)

    def evaluate(self, generation, progress=None):
        returns = np.append(self.member_returns, 0.0)
        n_tasks = len(generation.tasks)
        return Results(returns, np.ones(n_tasks, dtype=np.int64), np.ones(n_tasks))  # L2 penalties of 1

    def close(self):
        pass


class _RecordingStrategy:
    """Passes ``tell`` through, keeping the fitness it was given."""

    def __init__(self, strategy):
        self.strategy, self.told = strategy, []

    def __getattr__(self, name):
        return getattr(self.strategy, name)

    def tell(self, state, noise, indices, fitness):
        self.told.append(fitness.copy())
        return self.strategy.tell(state, noise, indices, fitness)


def test_nan_and_infinite_returns_are_ranked_last_and_reported(tmp_path):
    lines = []
    run = small_trainer(tmp_path, popsize=6, log=lines.append)
    run.on_generation = lambda record: lines.append(generation_line(record.row))
    try:
        run.evaluator.close()
        run.evaluator = _ScriptedReturns([10.0, np.nan, 30.0, np.inf, 20.0, -np.inf])
        run.strategy = _RecordingStrategy(run.strategy)
        assert run.train().value == "done"
    finally:
        run.close()
    (fitness,) = run.strategy.told
    assert np.isneginf(fitness[[1, 3, 5]]).all() and np.isfinite(fitness[[0, 2, 4]]).all()
    shaped = rank_std(fitness)
    assert np.argsort(shaped[[0, 2, 4]]).tolist() == [0, 2, 1]
    assert (shaped[[1, 3, 5]] < shaped[[0, 2, 4]].min()).all()  # below every finite member
    assert np.isfinite(run.state.theta).all()
    assert lines[-1].endswith(" | 3 non-finite returns ranked last")
    (row,) = files.read_metrics(tmp_path / "metrics.csv")
    assert row["nonfinite"] == "3" and float(row["fitness_max"]) < 30  # computed over the finite members


def test_nan_rewards_from_an_environment_never_reach_theta(tmp_path, monkeypatch, capsys):
    set_failing(monkeypatch, "nan", step=2)
    assert train(*SMALL, "--popsize", "8", "--threads", "1", "--generations", "2", "--folder", str(tmp_path)) == 0
    run_dir = only_run(tmp_path)
    assert "non-finite returns ranked last" in capsys.readouterr().out
    assert sum(int(row["nonfinite"]) for row in files.read_metrics(run_dir / "metrics.csv")) > 0
    assert np.isfinite(files.load_dat(run_dir / "last.dat")).all()


# --- Ctrl-C twice ----------------------------------------------------------------------------------


def test_a_second_ctrl_c_stops_at_once_even_with_a_stuck_environment(tmp_path):
    training = Training(*SMALL, "--threads", "2", "--generations", "2", "--folder", str(tmp_path),
                        env=failing("hang"))
    try:
        training.wait_for("run folder:")
        time.sleep(0.5)  # the workers are now stuck in the environment
        workers = descendants(training.process.pid)
        os.killpg(training.process.pid, signal.SIGINT)
        training.wait_for("interrupt: finishing this generation")
        os.killpg(training.process.pid, signal.SIGINT)
        assert training.finish(timeout=30) == 130
    finally:
        training.kill()
    run_dir = only_run(tmp_path)
    assert training.stderr[-1] == (f"train_static.py: stopped at once; saved files are intact "
                                   f"(resume with: {hint('train_static.py', '--resume', run_dir)})")
    assert still_running(workers) == set()
    with np.load(run_dir / "checkpoint.npz") as saved:
        assert int(saved["generation"]) == 0


# --- disks -----------------------------------------------------------------------------------------


def test_an_unwritable_folder_is_refused_before_anything_is_created(tmp_path, capsys):
    not_a_folder = tmp_path / "file"
    not_a_folder.write_text("")
    assert train(*SMALL, "--threads", "1", "--folder", str(not_a_folder / "runs")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"train_static.py: error: --folder {not_a_folder / 'runs'}: {not_a_folder} is not a writable folder"]
    assert sorted(path.name for path in tmp_path.iterdir()) == ["file"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into a read-only folder")
def test_a_read_only_folder_is_refused(tmp_path, capsys):
    folder = tmp_path / "read-only"
    folder.mkdir(mode=0o555)
    assert train(*SMALL, "--threads", "1", "--folder", str(folder / "runs")) == 2
    assert "is not a writable folder" in capsys.readouterr().err
    assert not list(folder.iterdir())


def test_a_full_disk_stops_the_run_naming_the_file_and_keeps_earlier_files(tmp_path, monkeypatch, capsys):
    assert train(*SMALL, "--threads", "1", "--generations", "2", "--folder", str(tmp_path)) == 0
    run_dir = only_run(tmp_path)
    before = {path.name: path.read_bytes() for path in run_dir.iterdir()}
    capsys.readouterr()

    real_fsync = os.fsync

    def disk_full(descriptor):
        if not (run_dir / "config.json").read_text().count("--resume"):  # the resume records itself first
            return real_fsync(descriptor)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(files.os, "fsync", disk_full)  # then every write fails after writing its bytes
    assert train("--resume", str(run_dir), "--generations", "4") == 2
    output = capsys.readouterr()
    assert not [line for line in output.out.splitlines() if line.startswith("error:")]
    assert output.err.splitlines() == [
        f"train_static.py: error: cannot write {run_dir / 'metrics.csv'}: No space left on device; {run_dir} keeps its "
        "checkpoint of generation 2 (every write is atomic: no file is torn); make space, then resume with: "
        f"{hint('train_static.py', '--resume', run_dir)}"]
    after = {path.name: path.read_bytes() for path in run_dir.iterdir()}
    assert after.pop("config.json") != before.pop("config.json")  # it lists the resume command
    assert after == before  # no torn or temporary file
    monkeypatch.undo()  # space is freed: the run goes on from its checkpoint
    assert train("--resume", str(run_dir), "--generations", "3") == 0
    assert [row["generation"] for row in files.read_metrics(run_dir / "metrics.csv")] == ["1", "2", "3"]


# --- a second interrupt while a generation's files are written ------------------------------------------


class _InterruptTwice:
    """Sends this process two SIGINTs as the loop hands it generation ``at``'s record, as an impatient user would."""

    def __init__(self, at: int):
        self.at, self.after_signals = at, []

    def __call__(self, record) -> None:
        row = record.row
        if row["generation"] == self.at:
            os.kill(os.getpid(), signal.SIGINT)
            os.kill(os.getpid(), signal.SIGINT)
            self.after_signals.append(row["generation"])  # still running: the second signal waits


def test_a_second_interrupt_waits_for_the_generations_files_then_stops_at_once(tmp_path):
    run = small_trainer(tmp_path, popsize=4, generations=5)
    reporter = _InterruptTwice(at=2)
    run.on_generation = reporter
    try:
        with pytest.raises(KeyboardInterrupt):
            run.train()
    finally:
        run.close()
    assert reporter.after_signals == [2]
    assert read_checkpoint(tmp_path / "checkpoint.npz").generation == 2  # saved before the stop
    assert [int(row["generation"]) for row in files.read_metrics(tmp_path / "metrics.csv")] == [1, 2]


def test_outside_the_files_a_second_interrupt_stops_at_once():
    with Interrupts() as interrupts:
        os.kill(os.getpid(), signal.SIGINT)
        assert interrupts.requested
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
        with pytest.raises(KeyboardInterrupt), interrupts.held():
            os.kill(os.getpid(), signal.SIGINT)
            reached = True  # the block runs to its end first
    assert reached
