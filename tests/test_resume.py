"""Resume: a run stopped and resumed is bit-for-bit the run that never stopped; kills never corrupt it."""

from __future__ import annotations

import os
import random
import re
import shlex
import signal
import subprocess
import time
from dataclasses import replace

import numpy as np
import pytest

import train_static
from es import runfolder
from es.runfolder import RunFolder
from report.machine import cpu_model, machines_text
from tests.run_helpers import (
    Training,
    assert_same_run,
    descendants,
    hint,
    only_run,
    small_trainer,
    still_running,
)

CARTPOLE = ("--environment", "CartPole-v1", "--popsize", "8", "--seed", "5")


def train(*argv: str) -> int:
    return train_static.main(list(argv))


@pytest.fixture(scope="module")
def straight_run(tmp_path_factory):
    """4 generations without a stop."""
    folder = tmp_path_factory.mktemp("straight")
    assert train(*CARTPOLE, "--threads", "1", "--generations", "4", "--folder", str(folder)) == 0
    return only_run(folder)


def test_resumed_run_matches_an_uninterrupted_one(tmp_path, straight_run):
    assert train(*CARTPOLE, "--threads", "1", "--generations", "2", "--folder", str(tmp_path)) == 0
    split = only_run(tmp_path)
    assert train("--resume", str(split), "--generations", "4") == 0
    assert_same_run(straight_run, split)


def test_each_start_and_resume_records_its_machine(tmp_path):
    """config.json's "machines": the CPU, its cores, the workers and the package versions of each start and
    resume, from the generation it began at (what metrics.csv's seconds were measured on)."""
    assert train(*CARTPOLE, "--threads", "1", "--generations", "2", "--folder", str(tmp_path)) == 0
    run = only_run(tmp_path)
    installed = RunFolder.existing(run).read_config()["versions"]
    assert {"python", "numpy", "gymnasium"} <= set(installed)
    here = {"cpu": cpu_model(), "cores": os.cpu_count(), "versions": installed}
    assert RunFolder.existing(run).read_config()["machines"] == [{"from_generation": 0, **here, "workers": 1}]
    assert train("--resume", str(run), "--generations", "3", "--threads", "2") == 0
    assert RunFolder.existing(run).read_config()["machines"] == [{"from_generation": 0, **here, "workers": 1},
                                                                  {"from_generation": 2, **here, "workers": 2}]
    assert machines_text(RunFolder.existing(run).read_config()["machines"]) == (
        f"{cpu_model()}, 1 worker; {cpu_model()}, 2 workers from generation 2")


def test_a_resume_with_other_packages_keeps_each_starts_versions(tmp_path, monkeypatch):
    """A resume under other installed packages records its own beside the start's: the start's entry keeps
    what it ran with, and the top-level "versions" is the resume's."""
    import cli.train

    assert train(*CARTPOLE, "--threads", "1", "--generations", "2", "--folder", str(tmp_path)) == 0
    run = only_run(tmp_path)
    started = RunFolder.existing(run).read_config()["versions"]
    resumed = {key: value for key, value in started.items() if key != "torch"} | {"numpy": "0.0-test"}
    monkeypatch.setattr(cli.train, "versions", lambda: dict(resumed))
    assert train("--resume", str(run), "--generations", "3") == 0
    config = RunFolder.existing(run).read_config()
    assert [entry["versions"] for entry in config["machines"]] == [started, resumed]
    assert config["versions"] == resumed


def test_the_machines_of_a_run_in_words():
    def entry(start, cpu, workers):
        return {"from_generation": start, "cpu": cpu, "cores": 16, "workers": workers}

    # a machine that goes on from the entry before is said once; a record that begins late says where
    assert machines_text([entry(0, "X", 2), entry(7, "X", 2), entry(9, "Y", 16)]) == "X, 2 workers; Y, 16 workers " \
                                                                                      "from generation 9"
    assert machines_text([entry(204, "X", 2)]) == "X, 2 workers from generation 204"
    assert machines_text([]) == ""


@pytest.fixture(scope="module")
def straight_every_3(tmp_path_factory):
    """9 generations without a stop, saving every 3 (the README's HalfCheetah command saves every 10)."""
    folder = tmp_path_factory.mktemp("straight_every_3")
    assert train(*CARTPOLE, "--threads", "1", "--generations", "9", "--print_every", "3", "--folder", str(folder)) == 0
    return only_run(folder)


@pytest.mark.parametrize("first", [6, 7])  # stopped at a save of --print_every, and by the end of its --generations
def test_a_run_saving_every_few_generations_resumes_bit_for_bit(tmp_path, straight_every_3, first):
    assert train(*CARTPOLE, "--threads", "1", "--generations", str(first), "--print_every", "3",
                 "--folder", str(tmp_path)) == 0
    split = only_run(tmp_path)
    assert train("--resume", str(split), "--generations", "9") == 0
    assert_same_run(straight_every_3, split)
    with np.load(split / "checkpoint.npz") as saved:  # the original's log: one value per save of every 3
        assert len(saved["fitness_log"]) == 3


def test_sigterm_with_print_every_resumes_through_the_printed_command(tmp_path, straight_every_3):
    training = Training(*CARTPOLE, "--threads", "1", "--generations", "9", "--print_every", "3",
                        "--folder", str(tmp_path / "cut"))
    try:
        training.wait_for("iter 4 ")  # between two saves of every 3
        training.process.send_signal(signal.SIGTERM)
        assert training.finish() == 130
    finally:
        training.kill()
    found = re.fullmatch(r"interrupted after generation (\d+); resume with: (.+)", training.stdout[-1])
    assert found and 4 <= int(found.group(1)) < 9, training.stdout
    command = shlex.split(found.group(2))
    resumed = subprocess.run(command, capture_output=True, text=True, timeout=300, check=False)
    assert resumed.returncode == 0, resumed.stderr
    assert_same_run(straight_every_3, only_run(tmp_path / "cut"))


def test_a_checkpoint_written_before_settings_were_recorded_resumes(tmp_path, straight_run):
    assert train(*CARTPOLE, "--threads", "1", "--generations", "2", "--folder", str(tmp_path)) == 0
    run_dir = only_run(tmp_path)
    with np.load(run_dir / "checkpoint.npz") as saved:  # as today's checkpoints are, without the record
        arrays = {key: saved[key] for key in saved.files if key not in ("settings", "settings_digest")}
    np.savez(run_dir / "checkpoint.npz", **arrays)
    assert train("--resume", str(run_dir), "--generations", "4") == 0
    assert_same_run(straight_run, run_dir)


def test_ctrl_c_finishes_the_generation_and_the_resumed_run_matches(tmp_path):
    """SIGINT to the whole process group, as a terminal sends it: workers ignore it, the run saves."""
    training = Training(*CARTPOLE, "--threads", "2", "--generations", "1000", "--folder", str(tmp_path / "cut"))
    try:
        training.wait_for("iter 1 ")
        workers = descendants(training.process.pid)
        os.killpg(training.process.pid, signal.SIGINT)
        assert training.finish() == 130
    finally:
        training.kill()
    assert len(workers) >= 2 and still_running(workers) == set()
    run_dir = only_run(tmp_path / "cut")
    last = training.stdout[-1]
    found = re.fullmatch(r"interrupted after generation (\d+); resume with: " + re.escape(hint("train_static.py"))
                         + r" --resume (.+)", last)
    assert found and found.group(2) == str(run_dir), training.stdout
    stopped = int(found.group(1))
    assert train("--resume", str(run_dir), "--generations", str(stopped + 1), "--threads", "1") == 0
    assert train(*CARTPOLE, "--threads", "1", "--generations", str(stopped + 1),
                 "--folder", str(tmp_path / "straight")) == 0
    assert_same_run(only_run(tmp_path / "straight"), run_dir)


def test_kill_9_of_the_run_takes_its_workers_and_leaves_a_resumable_checkpoint(tmp_path):
    training = Training(*CARTPOLE, "--threads", "2", "--generations", "1000", "--folder", str(tmp_path))
    try:
        training.wait_for("iter 1 ")
        workers = descendants(training.process.pid)
        training.process.kill()  # the main process only: its workers must follow it
        training.finish()
    finally:
        training.kill()
    assert len(workers) >= 2 and still_running(workers) == set()
    run_dir = only_run(tmp_path)
    with np.load(run_dir / "checkpoint.npz") as saved:  # generation 0 or 1, whichever was saved last
        reached = int(saved["generation"])
    assert train("--resume", str(run_dir), "--generations", str(reached + 1), "--threads", "1") == 0


def _save_forever(run) -> None:
    """In a forked child: checkpoints of generation g hold theta == g everywhere, until killed."""
    try:
        generation = run.state.generation
        while True:
            generation += 1
            run.state = replace(run.state, theta=np.full(run.policy.num_params, generation, np.float32),
                                generation=generation)
            run.save_checkpoint()
    finally:
        os._exit(1)


def test_kill_9_during_saves_always_leaves_a_loadable_checkpoint(tmp_path):
    run = small_trainer(tmp_path)
    delays = random.Random(0)
    try:
        run.save_checkpoint()
        for _ in range(15):
            child = os.fork()
            if child == 0:
                _save_forever(run)
            time.sleep(delays.uniform(0.002, 0.04))
            os.kill(child, signal.SIGKILL)
            os.waitpid(child, 0)
            run.restore(run.folder.load_checkpoint())  # also clears the temporary files of cut-short saves
            assert np.all(run.state.theta == run.state.generation)
            assert not list(tmp_path.glob(".*.tmp"))
    finally:
        run.close()


def test_resume_continues_a_run_that_stopped_with_an_error(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("FAILING_ENV_STEP", "3")
    monkeypatch.setenv("FAILING_ENV_HOW", "raise")
    failing = ("--environment", "tests.failing_env:FailingEnv-v0", "--popsize", "4", "--seed", "2", "--threads", "1")
    assert train(*failing, "--generations", "2", "--folder", str(tmp_path)) == 1
    run_dir = only_run(tmp_path)
    assert f"stopped; the checkpoint holds generation 0; resume with: {hint('train_static.py', '--resume', run_dir)}" \
        in capsys.readouterr().out
    monkeypatch.delenv("FAILING_ENV_STEP")  # the environment is repaired
    assert train("--resume", str(run_dir)) == 0
    assert [line.split(" |")[0] for line in capsys.readouterr().out.splitlines() if line.startswith("iter")] \
        == ["iter 1", "iter 2"]


def test_resuming_a_finished_run_says_there_is_nothing_to_do(tmp_path, capsys):
    assert train(*CARTPOLE, "--threads", "1", "--generations", "1", "--folder", str(tmp_path)) == 0
    assert train("--resume", str(only_run(tmp_path)), "--generations", "1") == 0
    assert "nothing to do" in capsys.readouterr().out


def test_resume_refuses_a_folder_that_is_not_a_run(tmp_path, capsys):
    assert train("--resume", str(tmp_path)) == 2
    assert capsys.readouterr().err.strip().endswith("not a run folder (needs config.json and checkpoint.npz)")


def test_runs_started_in_the_same_second_get_different_folders(tmp_path, monkeypatch):
    monkeypatch.setattr(runfolder.time, "strftime", lambda pattern: "20250101-120000")
    folders = [RunFolder.create(tmp_path, "CartPole-v1", 1) for _ in range(3)]
    assert [folder.name for folder in folders] == ["20250101-120000_CartPole-v1_seed1",
                                                    "20250101-120000_CartPole-v1_seed1-2",
                                                    "20250101-120000_CartPole-v1_seed1-3"]


def test_metrics_rows_after_the_checkpoint_are_dropped_on_resume(tmp_path, straight_run):
    """A kill between writing metrics.csv and the checkpoint: the resume redoes that generation."""
    assert train(*CARTPOLE, "--threads", "1", "--generations", "2", "--folder", str(tmp_path)) == 0
    run_dir = only_run(tmp_path)
    checkpoint_2 = (run_dir / "checkpoint.npz").read_bytes()
    assert train("--resume", str(run_dir), "--generations", "3") == 0
    (run_dir / "checkpoint.npz").write_bytes(checkpoint_2)  # as if killed before checkpoint 3 was written
    assert train("--resume", str(run_dir), "--generations", "4") == 0
    assert_same_run(straight_run, run_dir)


def test_a_metrics_row_cut_after_the_checkpoint_is_dropped_on_resume(tmp_path, straight_run):
    """A copy cut short in a row the checkpoint has not reached: that row is redone, never kept half empty."""
    assert train(*CARTPOLE, "--threads", "1", "--generations", "2", "--folder", str(tmp_path)) == 0
    run_dir = only_run(tmp_path)
    checkpoint_2 = (run_dir / "checkpoint.npz").read_bytes()
    assert train("--resume", str(run_dir), "--generations", "3") == 0
    (run_dir / "checkpoint.npz").write_bytes(checkpoint_2)
    text = (run_dir / "metrics.csv").read_text()
    (run_dir / "metrics.csv").write_text(text[:text.rstrip().rfind("\n") + 12])  # row 3 cut after 11 characters
    assert train("--resume", str(run_dir), "--generations", "4") == 0
    assert_same_run(straight_run, run_dir)


@pytest.mark.parametrize("damage", ["checkpoint", "metrics"])
def test_a_corrupt_run_folder_is_one_line_and_exit_2(tmp_path, capsys, damage):
    assert train(*CARTPOLE, "--threads", "1", "--generations", "1", "--folder", str(tmp_path)) == 0
    run_dir = only_run(tmp_path)
    if damage == "checkpoint":
        (run_dir / "checkpoint.npz").write_bytes(b"not a checkpoint")
    else:
        (run_dir / "metrics.csv").write_text("generation,fitness_mean\nsecond,1.0\n")
    capsys.readouterr()
    assert train("--resume", str(run_dir), "--generations", "2") == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and error[0].startswith("train_static.py: error: cannot resume")


def test_a_run_folder_of_the_previous_version_resumes(tmp_path, straight_run):
    """Before settings were sections, config.json was one flat object; such runs still resume."""
    import json

    assert train(*CARTPOLE, "--threads", "1", "--generations", "2", "--folder", str(tmp_path)) == 0
    run_dir = only_run(tmp_path)
    config = json.loads((run_dir / "config.json").read_text())
    flat = {"kind": config["policy"]["kind"], **config["env"], **config["es"], **config["run"]}
    flat = {key: value for key, value in flat.items() if key not in ("recipe_modules", "lr_floor", "sigma_decay",
                                                                      "sigma_floor", "fitness_l2")}
    (run_dir / "config.json").write_text(json.dumps(flat | {"command": config["command"], "resumed": []}))
    assert train("--resume", str(run_dir), "--generations", "4") == 0
    assert_same_run(straight_run, run_dir)
