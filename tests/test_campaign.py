"""The paper's campaign (``experiments/paper.py --budget``, ``experiments/campaign.py``), through the real script
on small CarRacing runs: a chunk stopped by SIGINT, committed with results/paper/.gitignore, cloned and
continued elsewhere, gives bit for bit the uninterrupted run; a budget stops at a generation boundary with
everything saved; the pid file; a second SIGINT; a second campaign refused; what a run folder keeps.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import experiments.paper as paper_script
from es.runfolder import read_checkpoint
from experiments import paper_campaign, paper_runs
from experiments.campaign import prune
from report.machine import cpu_model

ROOT = Path(__file__).resolve().parent.parent
ENV = {**os.environ, "SDL_VIDEODRIVER": "dummy", "PYTHONUNBUFFERED": "1"}
SMALL = ("carracing", "hebbian", "--popsize", "4", "--episodes", "1", "--threads", "2")
KEPT_WHILE_RUNNING = {"config.json", "checkpoint.npz", "metrics.csv"}


def paper(*args: str, folder: Path, budget: float = 10) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "experiments/paper.py", *args, "--folder", str(folder), "--budget",
                           str(budget)], cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=600)


def start(*args: str, folder: Path, budget: float = 10) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "experiments/paper.py", *args, "--folder", str(folder), "--budget",
                             str(budget)], cwd=ROOT, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)


def run_of(folder: Path) -> Path:
    (run,) = [path for path in folder.iterdir() if path.is_dir()]
    return run


def generations_recorded(run: Path) -> list[int]:
    if not (run_path := run / "metrics.csv").exists():
        return []
    with open(run_path, newline="") as handle:
        return [int(row["generation"]) for row in csv.DictReader(handle)]


def wait_for_generations(folder: Path, count: int, timeout: float = 300) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        runs = [path for path in folder.iterdir() if path.is_dir()] if folder.exists() else []
        if runs and len(generations_recorded(runs[0])) >= count:
            return
        time.sleep(0.2)
    raise AssertionError(f"no {count} generations in {folder} within {timeout} s")


def numbers(run: Path) -> tuple[dict[str, bytes], list[dict]]:
    """The final weight files' bytes, and metrics.csv without its timings."""
    weights = {path.name: path.read_bytes() for path in sorted(run.glob("last*.dat"))}
    with open(run / "metrics.csv", newline="") as handle:
        rows = [{key: value for key, value in row.items() if "seconds" not in key} for row in csv.DictReader(handle)]
    return weights, rows


def git(*args: str, cwd: Path) -> str:
    names = {"GIT_AUTHOR_NAME": "t", "GIT_AUTHOR_EMAIL": "t@t", "GIT_COMMITTER_NAME": "t", "GIT_COMMITTER_EMAIL": "t@t"}
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True, text=True,
                          env={**os.environ, **names}).stdout


def test_a_chunk_committed_and_continued_in_a_clone_is_the_uninterrupted_run(tmp_path):
    # a generation of this run takes about 0.15 s: 30 of them leave the SIGINT seconds to arrive before the
    # last one, however loaded the machine (with 4, a busy machine let the chunk finish before it came)
    total = 30
    generations = ("--generations", str(total))
    whole = paper(*SMALL, *generations, folder=tmp_path / "whole")
    assert whole.returncode == 0, whole.stdout[-2000:] + whole.stderr[-2000:]
    assert f"generation {total} of {total}, complete and evaluated" in whole.stdout

    repository = tmp_path / "repository"
    (repository / "results" / "paper").mkdir(parents=True)
    shutil.copy(ROOT / "results" / "paper" / ".gitignore", repository / "results" / "paper" / ".gitignore")
    folder = repository / "results" / "paper" / "carracing_hebbian_seed1"
    chunk = start(*SMALL, *generations, folder=folder)
    wait_for_generations(folder, 2)
    chunk.send_signal(signal.SIGINT)
    output, _ = chunk.communicate(timeout=120)
    assert chunk.returncode == 130, output[-2000:]
    assert not (repository / "results" / "paper" / "campaign.pid").exists()
    run = run_of(folder)
    done = read_checkpoint(run / "checkpoint.npz").generation
    assert 2 <= done < total and generations_recorded(run) == list(range(1, done + 1))
    assert {path.name for path in run.iterdir()} == KEPT_WHILE_RUNNING
    assert f"generation {done} of {total}, saved" in output and "continue with: python experiments/paper.py" in output

    git("init", "-q", cwd=repository)
    git("add", "-A", cwd=repository)
    git("commit", "-q", "-m", "chunk", cwd=repository)
    committed = set(git("ls-files", cwd=repository).split())
    relative = run.relative_to(repository)
    pages = {"results/paper/progress.md", "results/paper/carracing_curves.png"}  # written at the chunk's end
    assert committed == {"results/paper/.gitignore", *pages, *(f"{relative}/{name}" for name in KEPT_WHILE_RUNNING)}
    clone = tmp_path / "clone"
    git("clone", "-q", str(repository), str(clone), cwd=tmp_path)
    continued = paper(*SMALL, *generations, folder=clone / "results" / "paper" / "carracing_hebbian_seed1")
    assert continued.returncode == 0, continued.stdout[-2000:] + continued.stderr[-2000:]
    assert f"resuming {clone / relative} at generation {done} of {total}" in continued.stdout
    assert numbers(clone / relative) == numbers(run_of(tmp_path / "whole"))
    finished = {*KEPT_WHILE_RUNNING, "evaluation.json", "evaluation_best.json", "adaptation.png", "frames.png",
                "last_coeffs.dat", "last_CNN_parameters.dat"}
    assert {path.name for path in (clone / relative).iterdir()} == finished
    assert (clone / relative / "frames.png").read_bytes() == (run_of(tmp_path / "whole") / "frames.png").read_bytes()
    git("add", "-A", cwd=clone)  # the finished run is committed whole: the weights, the evaluation, its pictures
    assert set(git("ls-files", cwd=clone).split()) == {"results/paper/.gitignore", *pages,
                                                        *(f"{relative}/{name}" for name in finished)}
    assert (clone / relative / "evaluation.json").read_text() == (run_of(tmp_path / "whole") /
                                                                   "evaluation.json").read_text().replace(
        str(run_of(tmp_path / "whole")), str(clone / relative))


def test_a_budget_stops_at_a_generation_boundary_with_everything_saved(tmp_path):
    result = paper(*SMALL, "--generations", "1000", folder=tmp_path / "runs" / "x", budget=1)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    run = run_of(tmp_path / "runs" / "x")
    done = read_checkpoint(run / "checkpoint.npz").generation
    assert done >= 1 and generations_recorded(run) == list(range(1, done + 1))
    with open(run / "metrics.csv", newline="") as handle:
        trained = float(list(csv.DictReader(handle))[-1]["total_seconds"])
    assert trained <= 1 * 60  # the generations saved all ended within the budget, whatever the machine's load
    assert f"generation {done} of 1000, saved" in result.stdout
    assert {path.name for path in run.iterdir()} == KEPT_WHILE_RUNNING
    assert not (tmp_path / "runs" / "campaign.pid").exists()


def test_a_second_sigint_stops_at_once_and_the_last_save_stays_intact(tmp_path):
    """Stopped at once, the run keeps its last checkpoint (a metrics row written after it, if the stop came
    during a save, is dropped when the run continues); the next chunk continues it."""
    folder = tmp_path / "runs" / "x"
    larger = ("carracing", "hebbian", "--popsize", "32", "--threads", "2", "--episodes", "1")
    chunk = start(*larger, "--generations", "1000", folder=folder)
    wait_for_generations(folder, 1)
    assert int((tmp_path / "runs" / "campaign.pid").read_text()) == chunk.pid
    chunk.send_signal(signal.SIGINT)
    time.sleep(1.0)
    chunk.send_signal(signal.SIGINT)
    output, _ = chunk.communicate(timeout=120)
    assert chunk.returncode == 130, output[-2000:]
    assert "stopping the training at once" in output  # not waiting for the generation to end
    run = run_of(folder)
    checkpoint = read_checkpoint(run / "checkpoint.npz")
    recorded = generations_recorded(run)
    assert np.isfinite(checkpoint.theta).all() and recorded[:checkpoint.generation] == list(
        range(1, checkpoint.generation + 1)) and len(recorded) <= checkpoint.generation + 1
    assert not (tmp_path / "runs" / "campaign.pid").exists()
    continued = paper(*larger, "--generations", str(checkpoint.generation + 1), folder=folder)
    assert continued.returncode == 0, continued.stdout[-2000:] + continued.stderr[-2000:]
    assert generations_recorded(run) == list(range(1, checkpoint.generation + 2))


def test_a_second_campaign_is_refused_in_one_line(tmp_path):
    (tmp_path / "runs").mkdir()
    (tmp_path / "paper.py").write_text("import time\ntime.sleep(60)\n")  # a process that runs a paper.py
    holder = subprocess.Popen([sys.executable, str(tmp_path / "paper.py")])
    try:
        (tmp_path / "runs" / "campaign.pid").write_text(f"{holder.pid}\n")
        result = paper(*SMALL, "--generations", "2", folder=tmp_path / "runs" / "x")
    finally:
        holder.kill()
        holder.wait()
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stderr.strip() == (f"paper.py: error: a campaign is already running (pid {holder.pid}, in "
                                     f"{tmp_path / 'runs' / 'campaign.pid'}); wait for it to end, or stop it with: "
                                     f"kill -INT {holder.pid}")
    assert not (tmp_path / "runs" / "x").exists()
    assert (tmp_path / "runs" / "campaign.pid").read_text() == f"{holder.pid}\n"


def test_a_stale_pid_file_is_taken_over(tmp_path):
    (tmp_path / "runs").mkdir()
    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    (tmp_path / "runs" / "campaign.pid").write_text(ended.stdout)
    result = paper(*SMALL, "--generations", "1", folder=tmp_path / "runs" / "x")
    assert result.returncode == 0, result.stderr[-2000:]
    assert (f"campaign: {tmp_path / 'runs' / 'campaign.pid'} named process {ended.stdout.strip()}, which has ended (a "
            "campaign stopped without removing it); taking it over") in result.stdout
    assert not (tmp_path / "runs" / "campaign.pid").exists()


def test_a_live_process_that_is_not_a_campaign_is_never_advised_to_be_signalled(tmp_path):
    """A pid file naming a live process that is not a campaign (an id reused since the campaign that wrote it
    ended): refused, with how to remove the file, and no word of signalling that process."""
    (tmp_path / "runs").mkdir()
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (tmp_path / "runs" / "campaign.pid").write_text(f"{holder.pid}\n")
        result = paper(*SMALL, "--generations", "2", folder=tmp_path / "runs" / "x")
    finally:
        holder.kill()
        holder.wait()
    pid_file = tmp_path / "runs" / "campaign.pid"
    assert result.returncode == 2 and result.stderr.strip().startswith(
        f"paper.py: error: {pid_file} names process {holder.pid}, which is not a campaign ("), result.stderr
    assert result.stderr.strip().endswith(f"if no campaign is running, remove it (rm {pid_file}), then start again")
    assert "kill" not in result.stderr and not (tmp_path / "runs" / "x").exists()
    assert pid_file.read_text() == f"{holder.pid}\n"


def test_prune_keeps_what_continuing_and_evaluating_need(tmp_path):
    names = ["config.json", "checkpoint.npz", "metrics.csv", "evaluation.json", "evaluation_best.json",
             "adaptation.png", "frames.png", "last_coeffs.dat",
             "last_CNN_parameters.dat", "best_coeffs.dat", "HEBcoeffs__CarRacing-v0__rew_5__coeffs__3.dat", ".lock",
             "fitness.png", "Fitness_values_run_CarRacing-v0.npy"]
    for name in names:
        (tmp_path / name).write_text("x")
    removed = prune(tmp_path, complete=False)
    assert sorted(path.name for path in tmp_path.iterdir()) == sorted(names[:7])
    assert set(removed) == set(names[7:])
    (tmp_path / "last.dat").write_text("x")
    (tmp_path / "best.dat").write_text("x")
    assert prune(tmp_path, complete=True) == ["best.dat"]
    assert (tmp_path / "last.dat").exists()


def test_the_campaign_runs_its_entries_in_order_until_each_is_evaluated(tmp_path, monkeypatch, capsys):
    """``paper.py campaign --budget``: each entry of the campaign file continued until complete and evaluated,
    then the next; a second call finds nothing left to do."""
    entries = tmp_path / "campaign.toml"
    small = "--popsize 4 --generations 2 --episodes 1 --threads 2"
    entries.write_text(f'runs = ["carracing hebbian --seed 1 {small}", "carracing static --seed 1 {small}"]\n')
    monkeypatch.setattr(paper_runs, "CAMPAIGN", entries)
    monkeypatch.setattr(paper_runs, "RESULTS", tmp_path / "results")
    monkeypatch.setattr(sys, "executable", sys.executable)
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    assert paper_script.main(["campaign", "--budget", "10"]) == 0
    output = capsys.readouterr().out
    assert output.index("next run: carracing hebbian") < output.index("next run: carracing static")
    for kind in ("hebbian", "static"):
        run = run_of(tmp_path / "results" / f"carracing_{kind}_seed1")
        assert (run / "evaluation.json").exists() and read_checkpoint(run / "checkpoint.npz").generation == 2
        best = json.loads((run / "evaluation_best.json").read_text())  # from the checkpoint: best* are pruned
        assert best["weights"]["centre"] == "best" and best["seed"] == 2**31 and not list(run.glob("best*"))
    assert "every run of" in output and not (tmp_path / "results" / "campaign.pid").exists()
    assert paper_script.main(["campaign", "--budget", "10"]) == 0
    assert "next run" not in capsys.readouterr().out
    # a run evaluated before the best centre was (evaluation.json alone): the queue evaluates its best, and only that
    run = run_of(tmp_path / "results" / "carracing_static_seed1")
    (run / "evaluation_best.json").unlink()
    final = (run / "evaluation.json").read_bytes()
    assert paper_script.main(["campaign", "--budget", "10"]) == 0
    output = capsys.readouterr().out
    assert "next run: carracing static" in output and "evaluating the best centre" in output
    assert "evaluating the final centre" not in output and "training, for" not in output
    assert (run / "evaluation.json").read_bytes() == final and (run / "evaluation_best.json").exists()


def test_the_campaign_takes_only_its_budget_and_threads():
    result = subprocess.run([sys.executable, "experiments/paper.py", "campaign", "--budget", "5", "--seed", "2"],
                            cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and result.stderr.strip() == (
        "paper.py: error: campaign takes --budget MINUTES (and --threads) or --status, and its runs from "
        "experiments/paper/campaign.toml, not --seed")


def test_the_status_says_how_far_each_run_got(tmp_path, monkeypatch, capsys):
    entries = tmp_path / "campaign.toml"
    entries.write_text('runs = ["carracing static --seed 1 --popsize 4 --generations 3", "ant static --seed 1"]\n')
    monkeypatch.setattr(paper_runs, "CAMPAIGN", entries)
    monkeypatch.setattr(paper_runs, "RESULTS", tmp_path / "results")
    chunk = paper(*("carracing", "static", "--popsize", "4", "--generations", "3", "--episodes", "1"),
                  folder=tmp_path / "results" / "carracing_static_seed1", budget=10)
    assert chunk.returncode == 0, chunk.stderr[-2000:]
    assert paper_script.main(["campaign", "--status"]) == 0
    first, second, remaining = capsys.readouterr().out.strip().splitlines()
    run = run_of(tmp_path / "results" / "carracing_static_seed1")
    with open(run / "metrics.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    hours = sum(float(row["seconds"]) for row in rows) / 3600
    assert first.startswith(f"carracing static seed 1: {run}: generation 3 of 3 (evaluated); {hours:.2f} h of training")
    assert f"population mean {float(rows[-1]['fitness_mean']):.1f}" in first
    assert second == "ant static seed 1: not started; no completed run of ant static to project from"
    assert remaining == ("remaining: 1 run to train: not projected, no completed run of their kind yet: ant static "
                         "seed 1.")
    assert paper_script.main(["carracing", "curves", "--runs", str(tmp_path / "results")]) == 0
    assert capsys.readouterr().out.strip() == f"wrote {tmp_path / 'results' / 'carracing_curves.png'} (static seed 1)"
    assert (tmp_path / "results" / "carracing_curves.png").read_bytes().startswith(b"\x89PNG")
    assert paper_script.main(["ant", "curves", "--runs", str(tmp_path / "results")]) == 2


@pytest.mark.skipif(not Path("/proc/self/autogroup").exists(), reason="no autogroups: Linux's scheduler setting")
def test_a_chunk_gives_its_session_the_campaigns_niceness():
    """The training child runs in a session of its own, a scheduling group of its own where the kernel has
    autogroups: started under nice -n 19, the campaign ranks that whole group at 19, not only the child in it."""
    script = ("import os, subprocess, sys, time; from pathlib import Path\n"
              "sys.path.insert(0, sys.argv[1]); from experiments.campaign import share_niceness\n"
              "print(os.nice(7))\n"
              "child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(30)'],\n"
              "                         start_new_session=True)\n"
              "share_niceness(child.pid)\n"
              "print(Path(f'/proc/{child.pid}/autogroup').read_text().split()[-1]); child.kill()\n")
    done = subprocess.run([sys.executable, "-c", script, str(ROOT)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    niceness, group = done.stdout.split()  # 7 above the niceness the test runs at: 7 on its own
    assert group == niceness


def test_the_status_of_a_run_not_yet_complete_says_how_long_the_rest_takes(tmp_path, monkeypatch, capsys):
    """A chunk stopped early: the status gives the time of the remaining generations at the last ten's pace."""
    entries = tmp_path / "campaign.toml"
    entries.write_text('runs = ["carracing hebbian --seed 1 --popsize 4 --episodes 1 --generations 30"]\n')
    monkeypatch.setattr(paper_runs, "CAMPAIGN", entries)
    monkeypatch.setattr(paper_runs, "RESULTS", tmp_path / "results")
    folder = tmp_path / "results" / "carracing_hebbian_seed1"
    chunk = start(*SMALL, "--generations", "30", folder=folder)
    wait_for_generations(folder, 2)
    chunk.send_signal(signal.SIGINT)
    output, _ = chunk.communicate(timeout=120)
    assert chunk.returncode == 130, output[-2000:]
    run = run_of(folder)
    done = read_checkpoint(run / "checkpoint.npz").generation
    with open(run / "metrics.csv", newline="") as handle:
        last = list(csv.DictReader(handle))[:done][-10:]
    seconds, steps = [float(row["seconds"]) for row in last], [int(row["env_steps"]) for row in last]
    assert paper_script.main(["campaign", "--status"]) == 0
    line, remaining = capsys.readouterr().out.strip().splitlines()
    left = (30 - done) * sum(seconds) / len(seconds) / 3600
    # the bound: 4 members and the centre, 1 episode each, every one to CarRacing's 1000 steps, at the same cost
    # per step as the last generations'
    most = (30 - done) * 5 * 1000 * sum(seconds) / sum(steps) / 3600
    assert line.startswith(f"carracing hebbian seed 1: {run}: generation {done} of 30; ")
    assert line.endswith(f"; at that pace about {left:.1f} h more, at most {most:.1f} h if every episode ran to its "
                         f"time limit; on {cpu_model()}, 2 workers; no completed run of carracing hebbian --popsize 4 "
                         "--generations 30 to project from")
    assert remaining == ("remaining: 1 run to train: not projected, no completed run of their kind yet: carracing "
                         "hebbian seed 1.")

    # the chunk wrote the same, partial, beside the runs, before its pid file went: the pages a stop hook commits
    assert f"campaign: wrote {tmp_path / 'results' / 'progress.md'} and " in output
    with open(run / "metrics.csv", newline="") as handle:
        hours = sum(float(row["seconds"]) for row in csv.DictReader(handle) if int(row["generation"]) <= done) / 3600
    rows = (tmp_path / "results" / "progress.md").read_text().splitlines()
    (row,) = [row for row in rows if row.startswith("| [carracing hebbian seed 1](")]
    assert row.startswith(f"| [carracing hebbian seed 1](carracing_hebbian_seed1/{run.name}) | {done} of 30, "
                          f"**partial** | {hours:.2f} h | ")
    assert f"| about {left:.1f} h ({hours + left:.1f} h in all); at most {most:.1f} h ({hours + most:.1f} h) |" in row
    assert row.endswith(f"| no completed run of its kind | {float(last[-1]['fitness_mean']):.1f}, "
                        f"{float(last[-1]['center_return']):.1f} | {cpu_model()}, 2 workers |")
    # the campaign's next run, in its order
    assert "| carracing static seed 1 | not started | | | | no completed run of its kind | | |" in rows
    assert (tmp_path / "results" / "carracing_curves.png").read_bytes().startswith(b"\x89PNG")
    assert paper_script.main(["carracing", "curves", "--runs", str(tmp_path / "results")]) == 0
    assert capsys.readouterr().out.strip() == (f"wrote {tmp_path / 'results' / 'carracing_curves.png'} "
                                               f"(hebbian seed 1, partial: generation {done} of 30)")


def duration(hours: float) -> str:
    return f"{hours:.1f} h" if hours >= 1 else f"{hours * 60:.0f} min" if hours * 60 >= 1 else f"{hours * 3600:.1f} s"


def estimate(hours: list[float]) -> str:
    """"about 4.5 s (4.1–4.9 s)": the mean of ``hours``, the fastest and the slowest (one unit written once)."""
    return spread(sum(hours) / len(hours), min(hours), max(hours))


def spread(mean: float, fastest: float, slowest: float) -> str:
    low, high = duration(fastest), duration(slowest)
    if low == high:
        return f"about {duration(mean)}"
    if low.split()[1] == high.split()[1]:
        low = low.split()[0]
    return f"about {duration(mean)} ({low}–{high})"


def test_the_status_projects_each_remaining_run_from_the_completed_runs_of_its_kind(tmp_path, monkeypatch, capsys):
    """A run not yet complete, started or not, takes what the completed runs of its experiment, kind and settings
    took for the generations it has left: their mean, the fastest and the slowest; on 16 workers times the ratio of
    the car_racing record's projections, and no figure where no record projects the kind; the campaign's remaining
    runs added up, in the status and on the progress page."""
    from benchmarks import record as records
    from experiments import cost

    small = "--popsize 4 --episodes 1 --generations 30"
    entries = tmp_path / "campaign.toml"
    entries.write_text("runs = [" + ", ".join(f'"carracing hebbian --seed {seed} {small}"' for seed in (1, 2, 3, 4))
                       + f', "carracing static --seed 1 {small}"]\n')
    monkeypatch.setattr(paper_runs, "CAMPAIGN", entries)
    monkeypatch.setattr(paper_runs, "RESULTS", tmp_path / "results")
    results = tmp_path / "results"
    for seed in (1, 2):  # complete: trained as a chunk would, the evaluation left out (the projection reads none)
        command = ["train_hebb.py", "--config", "experiments/paper/carracing_hebbian.toml", "--folder",
                   str(results / f"carracing_hebbian_seed{seed}"), "--seed", str(seed), "--popsize", "4",
                   "--generations", "30", "--threads", "2"]
        done = subprocess.run([sys.executable, *command], cwd=ROOT, env=ENV, capture_output=True, text=True,
                              timeout=600)
        assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    chunk = start(*SMALL, "--seed", "3", "--generations", "30", folder=results / "carracing_hebbian_seed3")
    wait_for_generations(results / "carracing_hebbian_seed3", 2)
    chunk.send_signal(signal.SIGINT)
    output, _ = chunk.communicate(timeout=120)
    assert chunk.returncode == 130, output[-2000:]
    done = read_checkpoint(run_of(results / "carracing_hebbian_seed3") / "checkpoint.npz").generation
    assert 2 <= done < 30

    def seconds(seed: int) -> list[float]:
        with open(run_of(results / f"carracing_hebbian_seed{seed}") / "metrics.csv", newline="") as handle:
            return [float(row["seconds"]) for row in csv.DictReader(handle)]

    left = [sum(seconds(seed)[done:]) / 3600 for seed in (1, 2)]  # seed 3's remaining generations, as 1 and 2 took them
    whole = [sum(seconds(seed)) / 3600 for seed in (1, 2)]  # seed 4's: all of them
    path, record = records.newest("car_racing")
    factor = (record["measures"]["projection_fast_16_workers"]["median"]
              / record["measures"]["projection_fast_2_workers"]["median"])
    group = "carracing hebbian --popsize 4 --generations 30"

    def on_16(hours: list[float]) -> str:
        return spread(sum(hours) / len(hours) * factor, min(hours) * factor, max(hours) * factor)

    source = f"projected from {group} seeds 1, 2 ({cpu_model()}, 2 workers)"
    assert paper_script.main(["campaign", "--status"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 6 and lines[0].startswith("carracing hebbian seed 1: ") and lines[0].endswith(" workers")
    assert lines[2].endswith(f"; {source}: {estimate(left)} of training left; on 16 workers {on_16(left)}")
    assert lines[3] == (f"carracing hebbian seed 4: not started; {source}: {estimate(whole)} of training left; on 16 "
                        f"workers {on_16(whole)}")
    assert lines[4] == ("carracing static seed 1: not started; no completed run of carracing static --popsize 4 "
                        "--generations 30 to project from")
    # the runs added up: their means, their fastest and their slowest
    added = spread(sum(left) / 2 + sum(whole) / 2, min(left) + min(whole), max(left) + max(whole))
    assert lines[5].startswith(
        f"remaining: 3 runs to train: {added} of training for the 2 projected, each run projected from the completed "
        f"runs of its experiment and kind, on their machines ({cpu_model()}, 2 workers), the range adding up the "
        f"fastest of them, and the slowest; not projected, no completed run of their kind yet: carracing static seed "
        f"1. On 16 workers, {group} (2 runs): "), lines[5]
    on_16_added = spread(sum(left) / 2 * factor + sum(whole) / 2 * factor, min(left) * factor + min(whole) * factor,
                         max(left) * factor + max(whole) * factor)
    assert lines[5].endswith(
        f"(2 runs): {on_16_added}, their projection times {factor:.3g}, the ratio of the projections on 16 workers "
        f"and on 2 in the benchmark's record {path.relative_to(ROOT)} ({cost.SCALING[('carracing', 'hebbian')].how}).")

    paper_campaign.write_pages(results, "carracing")  # what a chunk writes at its end
    assert capsys.readouterr().out.startswith(f"campaign: wrote {results / 'progress.md'}")
    page = (results / "progress.md").read_text()
    assert f"| {estimate(left)}, from {group} seeds 1, 2 |" in page
    assert f"| carracing hebbian seed 4 | not started | | | | {estimate(whole)}, from {group} seeds 1, 2 | | |" in page
    assert "| carracing static seed 1 | not started | | | | no completed run of its kind | | |" in page
    link = Path(os.path.relpath(path, results)).as_posix()
    assert "\n**Remaining.** 3 runs to train: " in page and f"[{path.name}]({link})" in page

    monkeypatch.setattr(cost, "SCALING", {})  # no record projects the kind on 16 workers: no figure, and why
    assert paper_script.main(["campaign", "--status"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[3].endswith(f"{estimate(whole)} of training left; on 16 workers no figure: no benchmark record "
                             "measures or projects such runs on 16 workers")
    assert lines[5].endswith(f". On 16 workers no figure for {group} (2 runs): no benchmark record measures or "
                             "projects such runs on 16 workers.")


def test_a_generations_step_limit_is_its_episodes_each_to_its_time_limit(monkeypatch):
    """The bound on a run's remaining time: (members + centre) x episodes on every training environment, plus
    the centre's evaluation share, each episode to --max_episode_steps or else its registered limit."""
    import gymnasium as gym

    from experiments.progress import generation_step_limit

    def config(env_ids, cap=None, **es):
        return {"env": {"env_ids": env_ids, "max_episode_steps": cap},
                "es": {"popsize": 200, "episodes": 1, "eval_every": None, "eval_episodes": 10, **es}}

    assert generation_step_limit(config(["CarRacing-v3"])) == 201 * 1000
    # the damaged-ant experiment trains on two bodies: each member runs an episode on both
    assert generation_step_limit(config(["AntBulletEnv-v0", "AntAsymRightBulletEnv-v0"])) == 201 * 2000
    assert generation_step_limit(config(["CartPole-v1"], episodes=3)) == 201 * 3 * 500
    assert generation_step_limit(config(["CartPole-v1"], cap=200)) == 201 * 200  # the smaller limit counts
    assert generation_step_limit(config(["CartPole-v1"], cap=900)) == 201 * 500
    # 10 evaluation episodes every 4th generation: 3 a generation, rounded up
    assert generation_step_limit(config(["CartPole-v1"], eval_every=4)) == (201 + 3) * 500
    # an environment with no time limit, or one not registered here: no bound
    monkeypatch.setitem(gym.registry, "Unlimited-v0", dataclasses.replace(gym.registry["CartPole-v1"],
                                                                          id="Unlimited-v0", max_episode_steps=None))
    assert generation_step_limit(config(["CartPole-v1", "Unlimited-v0"])) is None
    assert generation_step_limit(config(["Unlimited-v0"], cap=300)) == 201 * 300
    assert generation_step_limit(config(["no_such_module_here:Thing-v0"])) is None
    # a module a config.json names is never imported: reading a run folder runs none of its code
    assert generation_step_limit(config(["this:Unregistered-v0"])) is None
    assert "this" not in sys.modules or not hasattr(sys.modules["this"], "s")
    assert generation_step_limit({"env": {"env_ids": ["CartPole-v1"]}}) is None  # a config without its settings


def test_a_chunks_pages_name_a_run_they_cannot_read_and_end_the_chunk_cleanly(tmp_path, capsys):
    """The progress page and the curves are written after the chunk's run is saved: a run folder beside it
    whose checkpoint cannot be read is named in one line, and nothing is raised, nothing written half."""
    broken = tmp_path / "carracing_static_seed1" / "20260101-000000_CarRacing-v0_seed1"
    broken.mkdir(parents=True)
    (broken / "checkpoint.npz").write_bytes(b"not a checkpoint")
    (broken / "config.json").write_text('{"run": {"generations": 300}}')
    paper_campaign.write_pages(tmp_path, "carracing")
    line = capsys.readouterr().out.strip()
    assert line.startswith(f"campaign: the progress page or the curves in {tmp_path} could not be written: "
                           f"RunFolderError: cannot resume from {broken / 'checkpoint.npz'}: not a readable checkpoint")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["carracing_static_seed1"]


NOT_STARTED = "ant static seed 1: not started; no completed run of ant static to project from"


def test_the_status_names_a_run_it_cannot_read_and_goes_on(tmp_path, monkeypatch, capsys):
    entries = tmp_path / "campaign.toml"
    entries.write_text('runs = ["carracing static --seed 1", "ant static --seed 1"]\n')
    monkeypatch.setattr(paper_runs, "CAMPAIGN", entries)
    monkeypatch.setattr(paper_runs, "RESULTS", tmp_path / "results")
    broken = tmp_path / "results" / "carracing_static_seed1" / "20260101-000000_CarRacing-v0_seed1"
    broken.mkdir(parents=True)
    (broken / "checkpoint.npz").write_bytes(b"not a checkpoint")
    (broken / "config.json").write_text('{"run": {"generations": 300}}')
    assert paper_script.main(["campaign", "--status"]) == 2
    captured = capsys.readouterr()
    assert captured.out.strip().splitlines()[0] == NOT_STARTED
    assert captured.err.strip().startswith(f"paper.py: error: carracing static seed 1: {broken} cannot be read "
                                           "(RunFolderError: cannot resume from")


@pytest.mark.parametrize("text, problem", [
    ('runs = ["carracing hebbian"', "Unclosed array"),
    ("x = 1\n", "has no list of runs"),
    ("runs = []\n", "has no list of runs"),
    ("runs = [1, 2]\n", "has no list of runs"),
    (None, "No such file or directory"),
    ('runs = ["c hebbian"]\n', "the run 'c hebbian': argument experiment: invalid choice: 'c'"),
    ('runs = ["carracing hebbian --popsize x"]\n', "the run 'carracing hebbian --popsize x': argument --popsize"),
    ('runs = ["carracing report"]\n', "the run 'carracing report' is not an experiment and a kind to train"),
    ('runs = ["campaign --budget 5"]\n', "the run 'campaign --budget 5' is not an experiment and a kind to train"),
])
@pytest.mark.parametrize("argv", [["campaign", "--status"], ["campaign", "--budget", "10"]])
def test_a_broken_campaign_file_is_named_in_one_line(tmp_path, monkeypatch, capsys, text, problem, argv):
    entries = tmp_path / "campaign.toml"
    if text is not None:
        entries.write_text(text)
    monkeypatch.setattr(paper_runs, "CAMPAIGN", entries)
    monkeypatch.setattr(paper_runs, "RESULTS", tmp_path / "results")
    assert paper_script.main(argv) == 2
    captured = capsys.readouterr()
    (line,) = captured.err.strip().splitlines()
    assert line.startswith(f"paper.py: error: {entries}") and problem in line, line
    assert line.endswith('a campaign file holds runs = ["EXPERIMENT KIND FLAGS...", ...], e.g. runs = ["carracing '
                         'hebbian --seed 2"]') or line.endswith("each run is an experiment, a kind and its flags, as "
                                                               "paper.py takes them"), line
    assert captured.out == "" and sorted(path.name for path in tmp_path.iterdir()) == (
        ["campaign.toml"] if text is not None else [])


@pytest.mark.parametrize("config, problem", [
    ("[1, 2]", "config.json is not a JSON object"),
    ('{"run": {"generations": "300"}}', "config.json: run.generations must be a whole number >= 1, got '300'"),
    ('{"run": {"generations": 300}, "machines": "AMD"}', "config.json: machines must be a list of objects with cpu, "
                                                          "workers, from_generation, got AMD"),
])
def test_the_status_and_a_chunks_pages_name_a_config_json_of_the_wrong_types(tmp_path, monkeypatch, capsys, config,
                                                                             problem):
    entries = tmp_path / "campaign.toml"
    entries.write_text('runs = ["carracing static --seed 1", "ant static --seed 1"]\n')
    monkeypatch.setattr(paper_runs, "CAMPAIGN", entries)
    monkeypatch.setattr(paper_runs, "RESULTS", tmp_path / "results")
    broken = tmp_path / "results" / "carracing_static_seed1" / "20260101-000000_CarRacing-v0_seed1"
    broken.mkdir(parents=True)
    (broken / "checkpoint.npz").write_bytes(b"not read: its config.json is read first")
    (broken / "config.json").write_text(config)
    assert paper_script.main(["campaign", "--status"]) == 2
    captured = capsys.readouterr()
    assert captured.out.strip().splitlines()[0] == NOT_STARTED
    assert captured.err.strip() == (f"paper.py: error: carracing static seed 1: {broken} cannot be read (ValueError: "
                                    f"{broken}/{problem})")
    paper_campaign.write_pages(tmp_path / "results", "carracing")  # what a chunk writes at its end
    assert capsys.readouterr().out.strip() == (f"campaign: the progress page or the curves in {tmp_path / 'results'} "
                                               f"could not be written: ValueError: {broken}/{problem}")
    assert sorted(path.name for path in (tmp_path / "results").iterdir()) == ["carracing_static_seed1"]


# a training child as the chunk sees it: it appends a metrics row per generation; its SIGINT handler is installed
# only after STARTUP seconds (a real one imports for seconds first: a signal before then stops it at once)
FAKE_TRAINING = """
import signal, sys, time
start = time.monotonic()
asked = []
def handler(signum, frame):
    asked.append(signum)
time.sleep({startup})
signal.signal(signal.SIGINT, handler)
for generation in range({first}, {first} + 3):
    time.sleep(0.8)
    with open(sys.argv[1], "a") as handle:
        handle.write(f"{{generation}},0.8\\n")
    if asked:
        sys.exit(130)
"""


def fake_chunk(tmp_path: Path, seconds: list[float], budget: float, startup: float = 1.0):
    from experiments import campaign

    metrics = tmp_path / "metrics.csv"
    metrics.write_text("generation,seconds\n" + "".join(f"{g},{s}\n" for g, s in enumerate(seconds, 1)))
    said = []
    code = campaign.Chunk([sys.executable, "-c", FAKE_TRAINING.format(startup=startup, first=len(seconds) + 1),
                           str(metrics)], time.monotonic() + budget, lambda: metrics, tmp_path, said.append).run()
    generations = [int(line.split(",")[0]) for line in metrics.read_text().splitlines()[1:]]
    return code, generations[len(seconds):], said


def test_one_slow_generation_does_not_set_the_pace(tmp_path):
    """A generation's expected time is the median of the last five: one generation slowed by a loaded machine
    (4000 s among 10 s ones) does not make a 60 s chunk stop early."""
    code, trained, said = fake_chunk(tmp_path, [10, 10, 10, 10, 4000], budget=60)
    assert code == 0 and trained == [6, 7, 8] and not any("no room" in line for line in said)


def test_a_chunk_with_room_for_one_generation_trains_it_before_it_asks(tmp_path):
    """Where the budget holds one generation but not two, the chunk asks the child to stop only once a generation
    of its own is saved: asked while the child was still starting, it would stop before training anything."""
    code, trained, said = fake_chunk(tmp_path, [20, 20, 20], budget=30, startup=1.5)
    assert code == 130 and trained[:1] == [4] and len(trained) <= 2
    assert any("no room for another generation" in line for line in said)
