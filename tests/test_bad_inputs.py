"""Bad input, through the real scripts as processes: flags, TOML, hand-edited config.json, crafted
checkpoints and journals, outputs aimed at a run's files, and faults.

Each case copies one small real run folder (CartPole-v1, popsize 4, 2 generations, observation
normalisation and Adam, so that every kind of array is in its checkpoint), damages it or aims a command
at it, runs the script, and asserts: exit code 2; one line on stderr, no traceback; a resume command
printed only where resuming can help; every file under the case's folder byte-identical before and
after (but those a case names as rewritten by design), and no file or folder added or removed (but
in the folder where a case starts a new run); no marker file from a payload. The journal cases need
the ER-MRL extra and skip without it; the full disk needs a small filesystem mounted (root).
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import json
import os
import pickle
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
BASE_ENV = {**os.environ, "SDL_VIDEODRIVER": "dummy", "MUJOCO_GL": "egl", "PYTHONUNBUFFERED": "1"}
MARKER = "PAYLOAD_RAN"
RUN = ("--environment", "CartPole-v1", "--popsize", "4", "--generations", "2", "--threads", "1", "--seed", "1",
       "--obs_norm", "--optimizer", "adam")


def trained_run(folder: Path) -> Path:
    """The run folder ``train_static.py`` makes in ``folder`` with ``RUN``."""
    result = subprocess.run([sys.executable, str(ROOT / "train_static.py"), *RUN, "--folder", str(folder)], cwd=ROOT,
                            env=BASE_ENV, check=False, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    (run,) = folder.iterdir()
    return run


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory) -> Path:
    """One real run, made once for the module; each case works on its own copy."""
    run = trained_run(tmp_path_factory.mktemp("bad_inputs_run"))
    (run / ".lock").unlink()  # held by the process that trained it, now gone
    return run


def snapshot(folder: Path) -> dict[str, str]:
    """Every path under ``folder``: a file's SHA-256, or 'folder'."""
    return {str(path.relative_to(folder)): hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else "folder"
            for path in sorted(folder.rglob("*"))}


# --- damage -------------------------------------------------------------------------------------


def edit_checkpoint(run: Path, **changes: Callable[[np.ndarray], np.ndarray]) -> None:
    """Rewrite checkpoint.npz with some arrays changed (``theta=lambda a: ...``; a dotted key as ``optimizer__m``)."""
    with np.load(run / "checkpoint.npz") as saved:
        arrays = {key: saved[key] for key in saved.files}
    for key, change in changes.items():
        key = key.replace("__", ".")
        arrays[key] = change(arrays[key].copy())
    np.savez(run / "checkpoint.npz", **arrays)


def set_first(value: float) -> Callable[[np.ndarray], np.ndarray]:
    def change(array: np.ndarray) -> np.ndarray:
        array.flat[0] = value
        return array
    return change


def edit_config(run: Path, section: str, key: str, value) -> None:
    data = json.loads((run / "config.json").read_text())
    data[section][key] = value
    (run / "config.json").write_text(json.dumps(data))


def drop_metrics_row(run: Path) -> None:
    lines = (run / "metrics.csv").read_text().splitlines(keepends=True)
    (run / "metrics.csv").write_text("".join(lines[:1] + lines[2:]))


def cut_metrics(run: Path) -> None:
    """metrics.csv cut in the middle of its last row (the checkpoint's generation), as a copy cut short leaves it."""
    text = (run / "metrics.csv").read_bytes()
    last_row = text.rstrip(b"\r\n").rfind(b"\n") + 1
    (run / "metrics.csv").write_bytes(text[:last_row + (len(text) - last_row) // 2])


def metrics_as_pipe(run: Path) -> None:
    (run / "metrics.csv").unlink()
    os.mkfifo(run / "metrics.csv")


def copy_config_of_seed(seed: int) -> Callable[[Path, Path], None]:
    """config.json as another seed's run of the same command wrote it."""
    return lambda run, work: edit_config(run, "run", "seed", seed)


def damage_settings_record(run: Path) -> None:
    edit_checkpoint(run, settings=lambda record: np.array(str(record).replace('"popsize":4', '"popsize":8')))


def raising_module(run: Path, work: Path) -> None:
    (work / "raising_module.py").write_text('raise RuntimeError("raising_module: broken on purpose")\n')


def hidden_reservoirpy(run: Path, work: Path) -> None:
    """A reservoirpy first on the path that cannot be imported, as where the extra is not installed."""
    (work / "hidden" / "reservoirpy").mkdir(parents=True)
    (work / "hidden" / "reservoirpy" / "__init__.py").write_text('raise ImportError("reservoirpy is hidden")\n')


@dataclass
class HeldLock:
    descriptor: int

    def release(self) -> None:
        os.close(self.descriptor)


def hold_lock(run: Path) -> HeldLock:
    """Hold the run's lock from this process, as a training process resuming it would."""
    import fcntl

    descriptor = os.open(run / ".lock", os.O_RDWR | os.O_CREAT)
    fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    return HeldLock(descriptor)


@dataclass
class SmallDisk:
    """A tmpfs mounted at ``path``, unmounted when the case is done."""

    path: Path

    def release(self) -> None:
        subprocess.run(["umount", str(self.path)], check=False)


@functools.cache
def can_mount() -> bool:
    """Whether this process may mount a small filesystem (root, with the capability to)."""
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    with tempfile.TemporaryDirectory() as folder:
        mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", folder], check=False,
                                 capture_output=True).returncode == 0
        if mounted:
            subprocess.run(["umount", folder], check=True)
    return mounted


DISK_LEFT = 8192  # bytes left free: config.json and metrics.csv fit, a weight file (35 KB) does not


def full_disk(run: Path, work: Path) -> SmallDisk:
    """The run on a small filesystem of its own, filled but for DISK_LEFT bytes; its lock file made already,
    as the resume would make it."""
    disk = work / "disk"
    disk.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(disk)], check=True)
    shutil.copytree(run, disk / run.name)
    shutil.rmtree(run)
    (disk / run.name / ".lock").touch()
    stats = os.statvfs(disk)
    (disk / "filler").write_bytes(bytes(stats.f_bavail * stats.f_frsize - DISK_LEFT))
    return SmallDisk(disk)


def on_disk(run: Path, work: Path) -> Path:
    return work / "disk" / run.name


# --- journals (the ER-MRL extra) ------------------------------------------------------------------

EVOLVE = ("--env_id", "CartPole-v1", "--h_test", "t", "--training_steps", "2048", "--nb_seeds", "1",
          "--sampler", "Cmaes", "--sampler_seed", "3")
STUDY = "CartPole-v1_t_2k_steps"


EXTRA = ("optuna", "cmaes", "reservoirpy", "stable_baselines3")
EXTRA_REASON = "the ER-MRL extra is optional: pip install -r requirements-reservoirs.txt"


def has_extra() -> bool:
    return all(importlib.util.find_spec(module) is not None for module in EXTRA)


def genuine_journal(work: Path, trials: int = 9) -> Path:
    """A CMA-ES study as evolve_res.py records it (its settings, sampler, search space), with a cheap
    objective instead of PPO. The sampler pickles its optimiser once a generation (6 trials for two
    parameters) has been told, from the 8th trial on."""
    import optuna

    from reservoirs.commands import evolve_res_parser, search_settings, search_space
    from reservoirs.study import journal_path, open_study

    args = evolve_res_parser("evolve_res.py").parse_args([*EVOLVE, "--nb_trials", "1"])
    space = search_space(args, 1, suffixed=False)
    previous = Path.cwd()
    os.chdir(work)
    try:
        optuna.logging.set_verbosity(optuna.logging.ERROR)
        study = open_study(STUDY, search_settings(args, space, env=args.env_id, del_obs=args.del_obs), "Cmaes", 3)
        study.optimize(lambda trial: -abs(np.log(space.sample(trial)[0].spectral_radius)), n_trials=trials)
        return work / journal_path(STUDY)
    finally:
        os.chdir(previous)


class Payload:
    """Unpickled, it creates the marker file: what a crafted journal would run."""

    def __init__(self, path: Path):
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def crafted_journal(work: Path) -> Path:
    """A genuine journal plus one finished trial whose CMA-ES optimiser attribute is a payload."""
    journal = genuine_journal(work)
    lines = [json.loads(line) for line in journal.read_text().splitlines()]
    worker, trial_id = lines[-1]["worker_id"], sum(1 for line in lines if line["op_code"] == 4)
    key = next(key for line in lines for key in line.get("system_attr", {}) if key.endswith("optimizer:0"))
    appended = [{"op_code": 4, "worker_id": worker, "study_id": 0, "datetime_start": "2026-01-01T00:00:00.000000"},
                {"op_code": 9, "worker_id": worker, "trial_id": trial_id,
                 "system_attr": {key: pickle.dumps(Payload(work / MARKER)).hex()}},
                {"op_code": 6, "worker_id": worker, "trial_id": trial_id, "state": 1, "values": [1.0],
                 "datetime_complete": "2026-01-01T00:00:01.000000"}]
    with open(journal, "a") as handle:
        handle.writelines(json.dumps(line) + "\n" for line in appended)
    return journal


def earlier_test_summary(work: Path) -> None:
    genuine_journal(work)
    models = work / "models" / "CartPole-v1_t"
    models.mkdir(parents=True)
    (models / "test_2k_steps_seed_0.json").write_text('{"earlier": true}\n')


# --- the cases ------------------------------------------------------------------------------------


@dataclass
class Case:
    argv: Callable[[Path, Path], list[str]]  # (run copy, case folder) -> script and its arguments
    expect: str  # in the error line
    prepare: Callable[[Path, Path], object] = lambda run, work: None
    env: dict = field(default_factory=dict)  # changes to the environment; None removes a variable
    extra: bool = False  # needs the ER-MRL extra
    resumable: bool = False  # the line says how to resume: resuming can help
    rewrites: tuple[str, ...] = ()  # the names of files the command rewrites by design (a resume's config.json)
    creates: str | None = None  # the folder under the case's where the command starts a new run
    mounts: bool = False  # needs to mount a small filesystem
    modules: tuple[str, ...] = ()  # optional packages it needs (a logger's extra)


def train(*words) -> Callable[[Path, Path], list[str]]:
    return lambda run, work: ["train_static.py", *[word(run, work) if callable(word) else word for word in words]]


def evaluate(*words) -> Callable[[Path, Path], list[str]]:
    return lambda run, work: ["evaluate_static.py", "--environment", "CartPole-v1", "--path_weights",
                              str(run / "last.dat"), *[word(run, work) if callable(word) else word for word in words]]


def resume(run: Path, work: Path) -> list[str]:
    return ["train_static.py", "--resume", str(run), "--generations", "3"]


def new_run(*words) -> Callable[[Path, Path], list[str]]:
    """A new run of popsize 4 on one core, for one generation, in the case's folder ``new``."""
    return train("--popsize", "4", "--generations", "1", "--threads", "1", "--seed", "1", *words, "--folder",
                 lambda run, work: str(work / "new"))


def seeds(folder: Callable[[Path, Path], Path]) -> Callable[[Path, Path], list[str]]:
    return lambda run, work: ["experiments/seeds.py", "--seeds", "1", "--", "train_static.py", "--environment",
                              "CartPole-v1", "--popsize", "4", "--generations", "1", "--folder", str(folder(run, work))]


def in_run(name: str) -> Callable[[Path, Path], str]:
    return lambda run, work: str(run / name)


def link_to_config(run: Path, work: Path) -> None:
    (work / "out.json").symlink_to(run / "config.json")


def resume_with(*words) -> Callable[[Path, Path], list[str]]:
    return lambda run, work: [*resume(run, work), *words]


def edit_record(key: str, value) -> Callable[[Path, Path], None]:
    """config.json with a key of the run's history (``machines``, ``resumed``) set to ``value``."""
    def prepare(run: Path, work: Path) -> None:
        data = json.loads((run / "config.json").read_text())
        data[key] = value
        (run / "config.json").write_text(json.dumps(data))
    return prepare


def write_config(text: str) -> Callable[[Path, Path], None]:
    return lambda run, work: (run / "config.json").write_text(text)


def evaluated(run: Path, work: Path) -> None:
    """The files an evaluation of the run (experiments/paper.py's) wrote into its folder."""
    (run / "evaluation.json").write_text('{"environments": []}\n')
    (run / "adaptation.png").write_bytes(b"\x89PNG earlier evaluation")
    (run / "frames.png").write_bytes(b"\x89PNG earlier frames")


def edit_metrics(old: bytes, new: bytes) -> Callable[[Path, Path], None]:
    def prepare(run: Path, work: Path) -> None:
        text = (run / "metrics.csv").read_bytes()
        (run / "metrics.csv").write_bytes(text.replace(old, new, 1) if old else text + new)
    return prepare


def fitness_mean_abc(run: Path, work: Path) -> None:
    lines = (run / "metrics.csv").read_text().splitlines(keepends=True)
    fields = lines[1].split(",")
    fields[1] = "abc"  # fitness_mean of generation 1
    (run / "metrics.csv").write_text(lines[0] + ",".join(fields) + "".join(lines[2:]))


def pid_file(text: str | None) -> Callable[[Path, Path], None]:
    """A campaign.pid beside the experiment's folder: holding ``text``, or a folder (None)."""
    def prepare(run: Path, work: Path) -> None:
        if text is None:
            (work / "campaign.pid").mkdir()
        else:
            (work / "campaign.pid").write_text(text)
    return prepare


def chunk(*words) -> Callable[[Path, Path], list[str]]:
    """A campaign chunk of a tiny CarRacing run in the case's folder ``x`` (its pid file: the case's)."""
    return lambda run, work: ["experiments/paper.py", "carracing", "hebbian", "--popsize", "4", "--episodes", "1",
                              "--generations", "1", "--folder", str(work / "x"), "--budget", "10", *words]


def seeds_with(*words) -> Callable[[Path, Path], list[str]]:
    return lambda run, work: ["experiments/seeds.py", *words, "--", "train_static.py", "--environment",
                              "CartPole-v1", "--popsize", "4", "--generations", "1", "--folder", str(work / "launch")]


WANDB_ONLINE = {"WANDB_MODE": "online", "WANDB_API_KEY": "0" * 40}  # a login, so that W&B would go online


CASES = {
    # flags and faults
    "threads far above the cores": Case(train(*RUN[:6], "--threads", "1000", "--folder", lambda r, w: str(w / "new")),
                                        "--threads 1000 would start 1000 worker processes"),
    "render without a display": Case(evaluate("--render"), "no display",
                                     env={"DISPLAY": None, "SDL_VIDEODRIVER": "dummy"}),
    "MUJOCO_GL that Gymnasium cannot render": Case(
        lambda run, work: ["evaluate_static.py", "--environment", "Ant-v5", "--path_weights", str(run / "last.dat"),
                           "--video", str(work / "ant.mp4")], "MUJOCO_GL=glx",
        env={"DISPLAY": None, "MUJOCO_GL": "glx"}),
    # outputs aimed at a run's files, or at an input
    "--json the checkpoint": Case(evaluate("--json", in_run("checkpoint.npz")), "checkpoint.npz of the run folder"),
    "--json the statistics": Case(evaluate("--json", in_run("last.obs_norm.npz")),
                                  "last.obs_norm.npz of the run folder"),
    "--json config.json": Case(evaluate("--json", in_run("config.json")), "config.json of the run folder"),
    "--json a link to config.json": Case(evaluate("--json", lambda r, w: str(w / "out.json")),
                                         "config.json of the run folder", prepare=link_to_config),
    "--plot a weight file": Case(evaluate("--plot", in_run("best.dat")), "best.dat of the run folder"),
    "--json the weight file": Case(evaluate("--json", in_run("last.dat")), "which this command reads"),
    "--video a new name without a video suffix": Case(evaluate("--video", lambda r, w: str(w / "v.json")),
                                                      "give a name ending in .mp4"),
    "--plot the run's fitness.png": Case(evaluate("--plot", in_run("fitness.png")), "fitness.png of the run folder"),
    "--video the metrics": Case(evaluate("--video", in_run("metrics.csv")), "metrics.csv of the run folder"),
    "--json and --plot one file": Case(evaluate("--json", lambda r, w: str(w / "a.json"), "--plot",
                                                lambda r, w: str(w / "a.json")), "are the same file"),
    "plot_run.py -o the metrics": Case(lambda run, work: ["plot_run.py", str(run), "-o", str(run / "metrics.csv")],
                                       "which this command reads"),
    "plot_run.py -o fitness.png": Case(lambda run, work: ["plot_run.py", str(run), "-o", str(run / "fitness.png")],
                                       "fitness.png of the run folder"),
    "plot_run.py -o x.jpg": Case(lambda run, work: ["plot_run.py", str(run), "-o", str(work / "x.jpg")],
                                 "give a name ending in .png"),
    "--json an earlier evaluation.json": Case(evaluate("--json", in_run("evaluation.json")),
                                              "evaluation.json of the run folder", prepare=evaluated),
    "--plot an earlier adaptation.png": Case(evaluate("--plot", in_run("adaptation.png")),
                                             "which exists: an output never replaces a run's file", prepare=evaluated),
    "--video an earlier frames.png": Case(evaluate("--video", in_run("frames.png")),
                                          "which exists: an output never replaces a run's file", prepare=evaluated),
    "plot_run.py -o an earlier adaptation.png": Case(
        lambda run, work: ["plot_run.py", str(run), "-o", str(run / "adaptation.png")],
        "adaptation.png of the run folder", prepare=evaluated),
    "--video where no file can be created": Case(evaluate("--video", "/sys/x.mp4"),
                                                 "--video /sys/x.mp4: /sys is not an existing writable folder"),
    "--json where no file can be created": Case(evaluate("--json", "/proc/x.json"),
                                                "--json /proc/x.json: /proc is not an existing writable folder"),
    "report_runs.py --out a run folder": Case(
        lambda run, work: ["report_runs.py", "--group", f"a={run}", "--group", f"b={run}", "--out", str(run)],
        "is the run folder"),
    # the other scripts' values and files
    "report_runs.py --seed -1": Case(lambda run, work: ["report_runs.py", "--group", f"a={run}", "--seed", "-1"],
                                     "--seed: must be a whole number from 0 to 2147483647, got -1"),
    "report_runs.py --seed 2**32": Case(
        lambda run, work: ["report_runs.py", "--group", f"a={run}", "--seed", "4294967296"],
        "--seed: must be a whole number from 0 to 2147483647, got 4294967296"),
    "plot_run.py on a metrics.csv that is not text": Case(
        lambda run, work: ["plot_run.py", str(run), "-o", str(work / "x.png")], "metrics.csv: cannot be read ('utf-8'",
        prepare=edit_metrics(b"", b"\xff\xfe\n")),
    "plot_run.py on a metrics.csv value that is not a number": Case(
        lambda run, work: ["plot_run.py", str(run), "-o", str(work / "x.png")],
        "metrics.csv holds a value that is not a number (could not convert string to float: 'abc')",
        prepare=fitness_mean_abc),
    "seeds.py past the largest seed": Case(seeds_with("--first_seed", "2147483647", "--seeds", "2"),
                                           "--first_seed 2147483647 with --seeds 2 runs past the largest seed"),
    "seeds.py --seeds 3000000000": Case(seeds_with("--seeds", "3000000000"),
                                        "--first_seed 1 with --seeds 3000000000 runs past the largest seed"),
    "seeds.py --seeds beyond memory": Case(seeds_with("--seeds", "2000000000"), "needs about"),
    "seeds.py --ray_address without --ray": Case(seeds_with("--ray_address", "auto"),
                                                 "--ray_address has an effect only with --ray"),
    # TOML
    "TOML syntax error": Case(
        train("--config", lambda r, w: str(w / "bad.toml"), "--folder", lambda r, w: str(w / "new")), "bad.toml",
        prepare=lambda run, work: (work / "bad.toml").write_text("[es\npopsize = 4\n")),
    "TOML value of the wrong type": Case(
        train("--config", lambda r, w: str(w / "bad.toml"), "--folder", lambda r, w: str(w / "new")), "popsize",
        prepare=lambda run, work: (work / "bad.toml").write_text('[es]\npopsize = "four"\n')),
    # hand-edited config.json
    "a standard-library recipe module": Case(resume, "standard library",
                                             prepare=lambda run, work: edit_config(run, "env", "recipe_modules",
                                                                                   ["this"])),
    "a module path in an environment id": Case(
        resume, "not a plain dotted module name",
        prepare=lambda run, work: edit_config(run, "env", "env_ids", ["../../evil:CartPole-v1"])),
    "a standard-library module in an environment id": Case(
        resume, "standard library", prepare=lambda run, work: edit_config(run, "env", "env_ids", ["antigravity:X-v0"])),
    "another optimizer in config.json": Case(resume, "not that of --optimizer sgd",
                                             prepare=lambda run, work: edit_config(run, "es", "optimizer", "sgd")),
    "obs_norm turned off in config.json": Case(resume, "does not normalise observations",
                                               prepare=lambda run, work: edit_config(run, "policy", "obs_norm", False)),
    "another popsize in config.json": Case(resume, "config.json differs from the settings its checkpoint was written "
                                                   "under: --popsize 8 (the run has 4)",
                                           prepare=lambda run, work: edit_config(run, "es", "popsize", 8)),
    "another seed's config.json": Case(resume, "--seed 2 (the run has 1)", prepare=copy_config_of_seed(2)),
    "machines an object in config.json": Case(resume, '"machines" must be a list of the machines it ran on (objects), '
                                                      "got an object", prepare=edit_record("machines", {})),
    "machines null in config.json": Case(resume, '"machines" must be a list', prepare=edit_record("machines", None)),
    "resumed a string in config.json": Case(resume, '"resumed" must be a list of commands (strings), got a string',
                                            prepare=edit_record("resumed", "x")),
    "a config.json that is a list, evaluated": Case(evaluate(), "config.json is not a JSON object",
                                                    prepare=write_config("[1, 2]")),
    "a config.json that is a string, evaluated": Case(evaluate(), "config.json is not a JSON object",
                                                      prepare=write_config('"x"')),
    "a config.json that is a list, resumed": Case(resume, "config.json is not a JSON object",
                                                  prepare=write_config("[1, 2]")),
    # flags of a tracker or a backend the resumed run does not use
    "--mlflow_uri on resume": Case(resume_with("--mlflow_uri", "sqlite:///x.db"),
                                   "--mlflow_uri has an effect only with --logger mlflow"),
    "--mlflow_experiment on resume": Case(resume_with("--mlflow_experiment", "x"),
                                          "--mlflow_experiment has an effect only with --logger mlflow"),
    "--wandb_project on resume": Case(resume_with("--wandb_project", "x"),
                                      "--wandb_project has an effect only with --logger wandb"),
    "--ray_address on resume": Case(resume_with("--ray_address", "auto"),
                                    "--ray_address has an effect only with --backend ray"),
    # loggers that cannot start: one line, and no run folder left behind
    "--mlflow_uri of no store MLflow knows": Case(
        new_run("--environment", "CartPole-v1", "--logger", "mlflow", "--mlflow_uri", "bogus://x"),
        "--logger mlflow: ", modules=("mlflow",)),
    "--mlflow_uri a bare path": Case(
        new_run("--environment", "CartPole-v1", "--logger", "mlflow", "--mlflow_uri", lambda r, w: str(w / "mlruns")),
        "--logger mlflow: ", env={"MLFLOW_ALLOW_FILE_STORE": None}, modules=("mlflow",)),
    "--mlflow_uri a file that is not a database": Case(
        new_run("--environment", "CartPole-v1", "--logger", "mlflow", "--mlflow_uri",
                lambda r, w: f"sqlite:///{w / 'notes.db'}"),
        "notes.db: the database cannot be opened (file is not a database)",
        prepare=lambda run, work: (work / "notes.db").write_text("not a database\n" * 20), modules=("mlflow",)),
    "WANDB_MODE of no such mode": Case(new_run("--environment", "CartPole-v1", "--logger", "wandb"),
                                       "--logger wandb: WANDB_MODE=bogus: W&B has no such mode",
                                       env={"WANDB_MODE": "bogus"}, modules=("wandb",)),
    # the campaign's pid file is data; a budget too short for a chunk
    "campaign.pid past the largest pid": Case(chunk(), "campaign.pid holds '99999999999', not the id of a process",
                                              prepare=pid_file("99999999999\n")),
    "campaign.pid holding -1": Case(chunk(), "campaign.pid holds '-1', not the id of a process this tool started; "
                                             "if no campaign is running, remove it", prepare=pid_file("-1\n")),
    "campaign.pid naming pid 1": Case(chunk(), "names process 1, which is not a campaign",
                                      prepare=pid_file("1\n")),
    "campaign.pid a folder": Case(chunk(), "campaign.pid is a folder, not the campaign's pid file",
                                  prepare=pid_file(None)),
    "--budget 0.001": Case(lambda run, work: chunk()(run, work)[:-2] + ["--budget", "0.001"],
                           "--budget 0.001 leaves no time for a chunk"),
    # crafted checkpoints and run files
    "NaN in theta": Case(resume, "theta holds NaN",
                         prepare=lambda run, work: edit_checkpoint(run, theta=set_first(np.nan))),
    "inf in theta": Case(resume, "theta holds NaN or infinite",
                         prepare=lambda run, work: edit_checkpoint(run, theta=set_first(np.inf))),
    "inf in the observation mean": Case(resume, "observations.sum holds NaN or infinite", prepare=lambda run, work:
                                        edit_checkpoint(run, observations__sum=set_first(np.inf))),
    "NaN in Adam's state": Case(resume, "optimizer.m holds NaN",
                                prepare=lambda run, work: edit_checkpoint(run, optimizer__m=set_first(np.nan))),
    "negative generation": Case(resume, "generation -1 is negative",
                                prepare=lambda run, work: edit_checkpoint(run, generation=lambda a: np.array(-1))),
    "theta of another size": Case(resume, "config.json's policy has",
                                  prepare=lambda run, work: edit_checkpoint(run, theta=lambda a: a[:-3],
                                                                            best_theta=lambda a: a[:-3],
                                                                            optimizer__m=lambda a: a[:-3],
                                                                            optimizer__v=lambda a: a[:-3])),
    "Adam's state of another size": Case(resume, "optimizer.v has shape",
                                         prepare=lambda run, work: edit_checkpoint(run, optimizer__v=lambda a: a[:5])),
    "a generation missing from metrics.csv": Case(resume, "metrics.csv holds generations",
                                                  prepare=lambda run, work: drop_metrics_row(run)),
    "a metrics.csv cut mid-row": Case(resume, "metrics.csv is damaged at line 3", prepare=lambda run, work:
                                      cut_metrics(run)),
    "a named pipe as metrics.csv": Case(resume, "metrics.csv is not a regular file",
                                        prepare=lambda run, work: metrics_as_pipe(run)),
    "a named pipe as the lock file": Case(resume, ".lock is not a regular file",
                                          prepare=lambda run, work: os.mkfifo(run / ".lock")),
    "a damaged record of the settings": Case(resume, "does not match its digest",
                                             prepare=lambda run, work: damage_settings_record(run)),
    "a checkpoint that is not one": Case(resume, "not a readable checkpoint",
                                         prepare=lambda run, work: (run / "checkpoint.npz").write_bytes(
                                             b"PK\x03\x04junk")),
    "NaN in the evaluated statistics": Case(evaluate(), "not an observation statistics file", prepare=lambda run, work:
                                            np.savez(run / "last.obs_norm.npz", mean=np.full(4, np.nan), std=np.ones(4),
                                                     clip=np.array(np.nan), observations=np.array(10))),
    "a folder another process holds": Case(resume, "in use by another process",
                                           prepare=lambda run, work: hold_lock(run)),
    # limits, and values that leave float32's range at run time
    "--sigma 1e308": Case(new_run("--environment", "CartPole-v1", "--sigma", "1e308"),
                          "--sigma must be in (0, 3.40282e+38], got 1e+308"),
    "--fitness_l2 1e308": Case(new_run("--environment", "CartPole-v1", "--fitness_l2", "1e308"),
                               "--fitness_l2 must be in [0, 3.40282e+38], got 1e+308"),
    "full CMA-ES on CartPole's 8832 parameters": Case(
        new_run("--environment", "CartPole-v1", "--strategy", "cma_es"),
        "keeps 7 matrices of 8832 x 8832 (the covariance, its eigenvectors, one outer product per member): about "
        "4.1 GiB, over its budget of 1.0 GiB"),
    "a sigma whose members leave float32": Case(
        new_run("--environment", "CartPole-v1", "--sigma", "3e38"),
        "CartPole-v1 failed in generation 1 with non-finite parameters for member 0", creates="new"),
    "an environment whose observations are NaN": Case(
        new_run("--environment", "tests.failing_env:FailingEnv-v0"),
        "FailingEnv-v0 failed in generation 1 with non-finite observations for member 0",
        env={"FAILING_ENV_HOW": "nan_obs", "FAILING_ENV_STEP": "0"}, creates="new"),
    "an environment whose observations turn NaN": Case(
        new_run("--environment", "tests.failing_env:FailingEnv-v0"),
        "FailingEnv-v0 failed in generation 1 with non-finite observations for member 0",
        env={"FAILING_ENV_HOW": "nan_obs", "FAILING_ENV_STEP": "3"}, creates="new"),
    "an lr whose step leaves float32": Case(new_run("--environment", "CartPole-v1", "--lr", "1e308"),
                                            "generation 1: the update is not finite (lr 1e+308", creates="new"),
    "a module that raises when imported": Case(
        new_run("--environment", "raising_module:X-v0"),
        "cannot import 'raising_module' for environment 'raising_module:X-v0': RuntimeError: raising_module: broken "
        "on purpose", prepare=raising_module, env={"PYTHONPATH": "."}),
    "a full disk while saving": Case(
        lambda run, work: ["train_static.py", "--resume", str(on_disk(run, work)), "--generations", "3"],
        "No space left on device", prepare=full_disk, resumable=True, rewrites=("config.json", "metrics.csv"),
        mounts=True),
    # the experiment scripts
    "seeds.py --folder a file": Case(seeds(lambda run, work: run / "config.json"), "is not a writable folder"),
    "seeds.py --folder under a file": Case(seeds(lambda run, work: run / "config.json" / "runs"),
                                           "is not a writable folder"),
    "compare.py without reservoirpy": Case(
        lambda run, work: ["experiments/reservoir_front/compare.py", "--seeds", "1", "--generations", "1", "--popsize",
                           "4", "--episodes", "1", "--threads", "1", "--folder", str(work / "front")],
        "the static+reservoir arm: --reservoir draws ER-MRL's reservoirs with reservoirpy, which is not installed",
        prepare=hidden_reservoirpy, env={"PYTHONPATH": "hidden"}),
    # a folder of its own: the repository's results/paper holds the campaign's runs, which a bad value resumes
    "paper.py --dry-run with a bad value": Case(lambda run, work: ["experiments/paper.py", "ant", "static", "--dry-run",
                                                                   "--popsize", "1", "--folder", str(work / "new")],
                                                "--popsize must be a whole"),
    "paper.py on a folder with other settings": Case(
        lambda run, work: ["experiments/paper.py", "ant", "static", "--dry-run", "--popsize", "8", "--folder",
                           str(work)],
        "--popsize 8 (the run has 4)"),
    "compare.py with --evaluate_on of other sizes": Case(
        lambda run, work: ["experiments/reservoir_front/compare.py", "--environment", "CartPole-v1", "--evaluate_on",
                           "CartPole-v1,Pendulum-v1", "--folder", str(work / "front"), "--dry-run"],
        "must share observation and action sizes"),
    # ER-MRL
    "an empty --h_test": Case(lambda run, work: ["scripts/evolve_res.py", *EVOLVE[:2], "--h_test", " ", *EVOLVE[4:],
                                                 "--nb_trials", "1"], "argument --h_test: is empty", extra=True),
    "a journal whose CMA-ES state runs code": Case(
        lambda run, work: ["scripts/evolve_res.py", *EVOLVE, "--nb_trials", "1"], "could run code",
        prepare=lambda run, work: crafted_journal(work), extra=True),
    "test.py on a journal whose CMA-ES state runs code": Case(
        lambda run, work: ["scripts/test.py", *EVOLVE[:4], "--HP_training_steps", "2048", "--training_timesteps", "64"],
        "could run code", prepare=lambda run, work: crafted_journal(work), extra=True),
    "test.py over an earlier test": Case(
        lambda run, work: ["scripts/test.py", *EVOLVE[:4], "--HP_training_steps", "2048", "--training_timesteps",
                           "2048"],
        "is from an earlier test", prepare=lambda run, work: earlier_test_summary(work), extra=True),
}


@dataclass
class Outcome:
    result: subprocess.CompletedProcess
    work: Path
    before: dict[str, str]


def run_case(case: Case, run_folder: Path, work: Path) -> tuple[list[str], dict, Path, object]:
    """Copy the run, apply the case's damage (in this thread: some change the working folder); the command."""
    run = work / run_folder.name
    shutil.copytree(run_folder, run)
    held = case.prepare(run, work)
    environ = {**BASE_ENV, **{key: value for key, value in case.env.items() if value is not None}}
    for key, value in case.env.items():
        if value is None:
            environ.pop(key, None)
    argv = case.argv(run, work)
    return [sys.executable, str(ROOT / argv[0]), *argv[1:]], environ, work, held


@pytest.fixture(scope="module")
def outcomes(run_folder, tmp_path_factory, request) -> dict[str, Outcome]:
    """The selected cases, prepared one by one, their commands run two at a time (or one per core)."""
    selected = {item.callspec.params["name"] for item in request.session.items
                if item.module is request.module and hasattr(item, "callspec")}
    names = [name for name in CASES if name in selected and runnable(CASES[name])]
    prepared = {name: run_case(CASES[name], run_folder, tmp_path_factory.mktemp("case")) for name in names}
    befores = {name: snapshot(work) for name, (_, _, work, _) in prepared.items()}

    def execute(name: str) -> subprocess.CompletedProcess:
        command, environ, work, _ = prepared[name]
        return subprocess.run(command, cwd=work, env=environ, check=False, capture_output=True, text=True, timeout=300)

    try:
        with ThreadPoolExecutor(max(2, os.cpu_count() or 1)) as pool:
            results = dict(zip(names, pool.map(execute, names)))
        yield {name: Outcome(results[name], prepared[name][2], befores[name]) for name in names}
    finally:  # a held lock, a mounted disk: once every case has been checked
        for *_, held in prepared.values():
            if hasattr(held, "release"):
                held.release()


def runnable(case: Case) -> bool:
    return ((not case.extra or has_extra()) and (not case.mounts or can_mount())
            and all(importlib.util.find_spec(module) is not None for module in case.modules))


def kept(files: dict[str, str], case: Case) -> dict[str, str]:
    """What must be as it was: every path but the files the case rewrites and the new run's folder."""
    return {path: digest for path, digest in files.items() if Path(path).name not in case.rewrites
            and (case.creates is None or Path(path).parts[0] != case.creates)}


@pytest.mark.parametrize("name", CASES)
def test_bad_input_is_one_line_exit_2_and_changes_nothing(name, outcomes):
    case = CASES[name]
    if not runnable(case):
        pytest.skip(EXTRA_REASON if case.extra else f"needs {', '.join(case.modules)}, an optional extra"
                    if case.modules else "mounting a small filesystem needs root")
    result, work = outcomes[name].result, outcomes[name].work
    lines = result.stderr.splitlines()
    assert result.returncode == 2, (result.returncode, result.stdout[-2000:], result.stderr[-3000:])
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert case.expect in lines[0], lines[0]
    assert "kill" not in lines[0]  # a process is never advised to be signalled: no input names one this tool started
    assert ("resume with:" in result.stdout + result.stderr) == case.resumable, lines[0]
    assert not (work / MARKER).exists(), "the payload ran"
    assert kept(snapshot(work), case) == kept(outcomes[name].before, case)
    assert "Beautiful is better than ugly" not in result.stdout  # the standard library's `this` was not imported
