"""The campaign's committed runs (results/paper/<experiment>_<kind>_seed<N>/<run>/) are the paper's command made
by this code: each run's recorded settings are its experiment file's with its seed, and training that command
again (``paper.py EXPERIMENT KIND --reproduce N``) gives the run's first generations row for row, every column
of metrics.csv but the timings; and the experiment files are the original README's command lines. This is the
check a reader of the shipped results makes (experiments/README.md, "Checking the shipped runs"); it fails the
day a change to the code moves the campaign's numbers.
"""

from __future__ import annotations

import csv
import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import train_hebb
import train_static
from cli.config import TrainConfig
from cli.hints import EVALUATE_SCRIPTS, TRAIN_SCRIPTS
from cli.train import config_from_args
from es.files import read_json
from es.runfolder import read_checkpoint
from experiments.campaign import MADE_WITH

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "results" / "paper"
RUNS = sorted(path.parent for path in RESULTS.glob("*_*_seed*/*/metrics.csv"))
GENERATIONS = 2  # each about 10 s of CarRacing on one worker: random networks end their episodes early
# a variant's run, 1: a variant changes settings or the episode, not the update that the paper's runs check over 2,
# and its episodes may run 1000 steps from the first generation (no burn-in: 5 min a generation on one worker)
VARIANT_GENERATIONS = 1
DERIVED = {"noise_size"}  # filled in by the training (the noise table's size), not given


def experiment_of(run: Path) -> tuple[str, str, int]:
    """``results/paper/carracing_hebbian_seed1/<run>`` -> ("carracing", "hebbian", 1); a variant's run
    (``ant_static_sigma_seed1``) -> ("ant", "static", 1), its variant given by ``variant_of``."""
    head, seed = run.parent.name.rsplit("_seed", 1)
    experiment, kind = head.split("_")[:2]
    return experiment, kind, int(seed)


def variant_of(run: Path) -> list[str]:
    """``--variant FILE`` for a run of a campaign entry with a variant (its file's name in the folder's), else []."""
    from experiments.paper_args import campaign_entries

    head = run.parent.name.rsplit("_seed", 1)[0]
    files = {Path(entry.variant).stem: entry.variant for entry in campaign_entries() if entry.variant}
    name = head.split("_", 2)[2] if head.count("_") >= 2 else None
    return [] if name is None else ["--variant", str(Path(files[name]).relative_to(ROOT))]


def paper_command(run: Path) -> list[str]:
    """The campaign's command for this run (experiments/paper.py's ``train_command`` for a new run), without
    its script."""
    from argparse import Namespace

    from experiments.paper_runs import variant_flags

    experiment, kind, seed = experiment_of(run)
    variant = variant_of(run)
    changes = variant_flags(Namespace(variant=str(ROOT / variant[1]))) if variant else []
    return ["--config", f"experiments/paper/{experiment}_{kind}.toml", *changes, "--seed", str(seed),
            "--folder", str(run.parent.relative_to(ROOT))]


PARSERS = {"static": train_static.build_parser, "hebbian": train_hebb.build_parser}  # each kind's training script's


def run_id(run: Path) -> str:
    return run.parent.name


# the original code's README commands for the paper's CarRacing runs (docs/original.md), as this tool takes them
ORIGINAL = {
    "carracing_hebbian": "train_hebb.py --environment CarRacing-v0 --hebb_rule ABCD_lr --generations 300 --popsize 200 "
                         "--print_every 1 --init_weights uni --lr 0.2 --sigma 0.1 --decay 0.995 --threads -1 "
                         "--distribution normal",
    "carracing_static": "train_static.py --environment CarRacing-v0 --generations 300 --popsize 200 --print_every 1 "
                        "--lr 0.2 --sigma 0.1 --decay 0.995 --threads -1",
}


@pytest.mark.parametrize("experiment", sorted(ORIGINAL))
def test_the_experiment_files_are_the_original_commands(experiment):
    """experiments/paper/carracing_*.toml give exactly the settings of the original README's command lines."""
    kind = experiment.split("_")[1]
    _, *words = ORIGINAL[experiment].split()  # (the kind's script, train_hebb.py or train_static.py)
    parser = PARSERS[kind]()
    same = ["--seed", "1", "--folder", "runs"]
    original = config_from_args(kind, parser.parse_args([*words, *same]))
    from_file = config_from_args(kind, parser.parse_args(["--config", f"experiments/paper/{experiment}.toml", *same]))
    assert from_file.to_dict() == original.to_dict()  # every setting, the generations and workers included


ASKED = """
import json, sys

from cli.train import config_from_args
import train_hebb, train_static

parser = {"static": train_static, "hebbian": train_hebb}[sys.argv[1]].build_parser()
print(json.dumps(config_from_args(sys.argv[1], parser.parse_args(sys.argv[2:])).fixed()))
"""


def asked_settings(run: Path) -> dict:
    """The settings a resume may not change that the run's campaign command asks for, as its training script reads
    them (as config.json holds them: lists, not tuples). A variant's in a process of its own: a module its
    environment ids name registers its recipe in the process that imports it, and every later config of that
    process records the module (``envs.custom_recipe_modules``)."""
    kind = experiment_of(run)[1]
    if not variant_of(run):
        return json.loads(json.dumps(config_from_args(kind, PARSERS[kind]().parse_args(paper_command(run))).fixed()))
    done = subprocess.run([sys.executable, "-c", ASKED, kind, *paper_command(run)], cwd=ROOT, capture_output=True,
                          text=True, env={**os.environ, "SDL_VIDEODRIVER": "dummy"}, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("run", RUNS, ids=run_id)
def test_a_committed_run_has_the_papers_settings(run):
    asked = asked_settings(run)
    recorded = json.loads(json.dumps(TrainConfig.from_dict(read_json(run / "config.json")).fixed()))
    differing = {key: (recorded.get(key), asked.get(key)) for key in {*recorded, *asked} - DERIVED
                 if recorded.get(key) != asked.get(key)}
    assert differing == {}, f"{run}: settings that are not the paper's command (recorded, asked): {differing}"


def paper(*args: str, root: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "experiments/paper.py", *args], cwd=root, capture_output=True, text=True,
                          env={**os.environ, "SDL_VIDEODRIVER": "dummy"}, timeout=600)


def made_with(run: Path) -> dict | None:
    """The label of a run made by older code (``made_with.json``): its commit and the CPUs it reproduces on."""
    path = run / MADE_WITH
    return read_json(path) if path.exists() else None


def avx512() -> bool:
    """Whether this process computes as the labelled runs' code did on their CPUs: numpy's float64 arctan2 in its
    AVX-512 loop (a CPU with AVX-512, not turned off by NPY_DISABLE_CPU_FEATURES) and OpenBLAS's kernels for the
    CPU (no OPENBLAS_CORETYPE)."""
    from numpy.lib.introspect import opt_func_info
    loop = opt_func_info(func_name="arctan2", signature="float64")["arctan2"]["ddd"]["current"]
    return loop == "X86_V4" and "OPENBLAS_CORETYPE" not in os.environ


def one_of_each(runs: list[Path]) -> list[Path]:
    """Every labelled run (checked with its commit's code, on the CPUs its label names), and of each experiment,
    kind and variant the lowest seed that today's code made: the other seeds differ from it only by the seed."""
    labelled = [run for run in runs if made_with(run) is not None]
    groups: dict[str, list[Path]] = {}
    for run in runs:
        if run not in labelled:
            groups.setdefault(run.parent.name.rsplit("_seed", 1)[0], []).append(run)
    return sorted([*(min(group, key=lambda run: experiment_of(run)[2]) for group in groups.values()), *labelled])


def pytest_generate_tests(metafunc):
    """The committed runs trained again: every one with ``--every-run`` (CI's step 4, where numpy and OpenBLAS take
    other code), else ``one_of_each`` (a whole pass is more than half an hour on one core, and grows with the
    campaign)."""
    if metafunc.definition.name == "test_the_papers_command_gives_a_committed_runs_first_generations_again":
        runs = RUNS if metafunc.config.getoption("every_run") else one_of_each(RUNS)
        metafunc.parametrize("run", runs, ids=[run_id(run) for run in runs])


def test_the_papers_command_gives_a_committed_runs_first_generations_again(run, tmp_path):
    """``paper.py EXPERIMENT KIND --reproduce N``: the experiment's command trained again, compared row by row; for
    a run labelled as made by older code, that code's command, on the CPUs its label names (x86-64 with
    AVX-512), its first generation: the label's claim checked."""
    experiment, kind, seed = experiment_of(run)
    count = min(VARIANT_GENERATIONS if variant_of(run) else GENERATIONS,
                read_checkpoint(run / "checkpoint.npz").generation)  # (a run just started: fewer)
    if count == 0:
        pytest.skip(f"{run.relative_to(ROOT)} has no generation saved yet")
    root, label = ROOT, made_with(run)
    if label is not None:
        assert label["reproduces_on"].startswith("x86-64 CPUs with AVX-512"), label  # the one label checked here
        if not avx512():
            pytest.skip(f"{run.relative_to(ROOT)} reproduces on {label['reproduces_on']} (its {MADE_WITH})")
        archive = subprocess.run(["git", "archive", "--format=tar", label["commit"]], cwd=ROOT, capture_output=True)
        if archive.returncode != 0:
            pytest.skip(f"commit {label['commit'][:12]} (its {MADE_WITH}) is not in this clone's history")
        subprocess.run(["tar", "-x", "-C", str(tmp_path)], input=archive.stdout, check=True)
        root, count = tmp_path, 1
    done = paper(experiment, kind, *variant_of(run), "--seed", str(seed), "--reproduce", str(count), "--threads",
                 "1", root=root)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == (
        f"generations 1-{count}: every column but the timings is {run.relative_to(ROOT)}'s")


def first_generation_steps(run: Path) -> int:
    with open(run / "metrics.csv", newline="") as handle:
        return int(next(csv.DictReader(handle))["env_steps"])


def test_a_labelled_run_differs_under_todays_code_and_says_where_it_reproduces():
    """The committed runs made by older code are labelled because today's code gives other last bits: here they
    differ at generation 1, and ``--reproduce`` names the commit and CPUs of the label."""
    labelled = [run for run in RUNS if made_with(run) is not None]
    if not labelled:
        pytest.skip("no committed run is labelled as made by older code")
    run = min(labelled, key=first_generation_steps)  # the quickest to train again
    experiment, kind, seed = experiment_of(run)
    done = paper(experiment, kind, "--seed", str(seed), "--reproduce", "1", "--threads", "1")
    assert done.returncode == 1, done.stdout[-2000:] + done.stderr[-2000:]
    last = done.stdout.strip().splitlines()[-1]
    assert last.startswith(f"generation 1 differs from {run.relative_to(ROOT)}: ")
    assert last.endswith(f"(the run was made by the code at commit {made_with(run)['commit'][:12]}, and reproduces "
                         f"with it on {made_with(run)['reproduces_on']}: see its {MADE_WITH})")


def test_the_commands_name_the_repositorys_files_from_its_root_and_paper_runs_from_anywhere(tmp_path):
    """paper.py gives its children (which run in the repository's root) the root's files by paths relative to
    it, so a command a run records (config.json, evaluation.json) runs as written in any checkout; and paper.py
    itself runs from any directory: here a dry run from elsewhere of a finished run (its resume checked against
    its config.json) and of a new seed (its experiment file read)."""
    run = next(run for run in RUNS if (run / "evaluation.json").exists() and not variant_of(run))
    experiment, kind, seed = experiment_of(run)
    train, evaluate = TRAIN_SCRIPTS[kind], EVALUATE_SCRIPTS[kind]
    new = f"results/paper/{experiment}_{kind}_seed99"
    # the committed run's evaluation is done: an output never replaces a run's file, so only a centre not yet
    # evaluated (evaluation_best.json missing) is evaluated again
    best_missing = not (run / "evaluation_best.json").exists()
    for asked, expected, run_dir, evaluations in (
            (seed, ["--resume", run.relative_to(ROOT).as_posix()], run.relative_to(ROOT).as_posix(),
             ["evaluation_best.json"] if best_missing else []),
            (99, ["--config", f"experiments/paper/{experiment}_{kind}.toml", "--folder", new], f"{new}/<run folder>",
             ["evaluation.json", "evaluation_best.json"])):
        done = subprocess.run([sys.executable, str(ROOT / "experiments" / "paper.py"), experiment, kind, "--seed",
                               str(asked), "--dry-run"], cwd=tmp_path, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
        commands = [shlex.split(line.removeprefix("$ ")) for line in done.stdout.splitlines() if line.startswith("$ ")]
        assert [command[1] for command in commands] == [train] + [evaluate] * len(evaluations)
        assert commands[0][2:] == [*expected, "--seed", str(asked)]
        assert [command[command.index("--json") + 1] for command in commands[1:]] == [
            f"{run_dir}/{name}" for name in evaluations]
        if asked == seed:
            assert (f"# the final centre is evaluated already: {run_dir}/evaluation.json (remove it to evaluate "
                    "again)") in done.stdout
        assert all(not word.startswith(str(ROOT)) for command in commands for word in command[1:])
    assert not any(tmp_path.iterdir())  # a dry run writes nothing, where it runs either


def test_reproduce_names_the_first_generation_that_differs(tmp_path):
    """--reproduce on a small run of its own: identical; then with the run's metrics.csv as another machine
    might have written it (generation 2's mean otherwise), exit 1 naming that generation and column; and the
    refusals: more generations than the run saved, other settings than the run's, no run at all."""
    small = ("carracing", "hebbian", "--popsize", "4", "--threads", "1", "--folder", str(tmp_path / "run"))
    made = paper(*small, "--generations", "3", "--episodes", "1")
    assert made.returncode == 0, made.stderr[-2000:]
    same = paper(*small, "--reproduce", "3")
    assert same.returncode == 0, same.stderr[-2000:]
    (run,) = [path for path in (tmp_path / "run").iterdir() if path.is_dir()]
    assert same.stdout.strip().splitlines()[-1] == f"generations 1-3: every column but the timings is {run}'s"
    with open(run / "metrics.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    mean = rows[1]["fitness_mean"]
    rows[1]["fitness_mean"] = "6.25"
    with open(run / "metrics.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    other = paper(*small, "--reproduce", "3")
    assert other.returncode == 1
    assert other.stdout.strip().splitlines()[-1] == (
        f"generation 2 differs from {run}: fitness_mean {mean} here, 6.25 in the run")
    longer = paper(*small, "--reproduce", "4")
    assert (longer.returncode, longer.stderr.strip()) == (
        2, f"paper.py: error: {run} has 3 generations saved; give --reproduce 3 or less")
    wider = paper(*small[:2], "--popsize", "6", *small[4:], "--reproduce", "2")
    assert wider.returncode == 2 and wider.stderr.strip().endswith("--popsize 6 (the run has 4)"), wider.stderr
    nothing = paper(*small[:-1], str(tmp_path / "none"), "--reproduce", "2")
    assert (nothing.returncode, nothing.stderr.strip()) == (
        2, f"paper.py: error: no run in {tmp_path / 'none'} to reproduce; train one first")
    damaged = tmp_path / "damaged"
    shutil.copytree(tmp_path / "run", damaged)
    (next(damaged.iterdir()) / "metrics.csv").unlink()
    unreadable = paper(*small[:-1], str(damaged), "--reproduce", "2")
    assert unreadable.returncode == 2 and len(unreadable.stderr.strip().splitlines()) == 1, unreadable.stderr
    assert "metrics.csv" in unreadable.stderr
    for words in (("campaign", "--reproduce", "2"), ("carracing", "report", "--reproduce", "2"),
                  ("carracing", "hebbian", "--reproduce", "2", "--budget", "5"),
                  ("carracing", "hebbian", "--reproduce", "2", "--generations", "5")):
        refused = paper(*words)
        assert refused.returncode == 2 and len(refused.stderr.strip().splitlines()) <= 2, refused.stderr
