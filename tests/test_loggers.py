"""``--logger``: a CartPole run sent to W&B (offline: no login here) and to a local MLflow store, read back
through each library's own reader (``wandb leet inspect --json``, W&B's reader of its .wandb files; MLflow's
``MlflowClient``) and compared with metrics.csv, the run split by a resume: every generation once, the
settings once, the figures and final weights as artefacts, the tracker's run continued under the id that
config.json records. Then the one-line refusals: a tracker not installed, a flag of a logger not chosen,
an MLflow run that is not in the store.

W&B and MLflow are optional extras (requirements-wandb.txt, requirements-mlflow.txt): their cases skip
without them, naming the extra; the missing-package cases hide the package and run everywhere.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest

import train_static
from es.files import METRICS_COLUMNS, read_metrics
from tests.extras import need
from tests.run_helpers import only_run

ROOT = Path(__file__).resolve().parent.parent
CARTPOLE = ("--environment", "CartPole-v1", "--popsize", "4", "--seed", "3", "--threads", "1")


def main(*argv) -> tuple[int, str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        try:
            code = train_static.main([str(word) for word in argv])
        except SystemExit as stop:  # argparse's refusals
            code = stop.code
    return code, out.getvalue()


def split_run(tmp_path: Path, *loggers: str, monkeypatch) -> Path:
    """2 generations, then resumed to 4: the run folder."""
    for name in ("WANDB_API_KEY", "WANDB_MODE", "MLFLOW_TRACKING_URI"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("NETRC", str(tmp_path / "no-netrc"))  # no W&B login here, whatever this machine has
    code, output = main(*CARTPOLE, "--generations", 2, "--folder", tmp_path / "runs", "--logger", *loggers)
    assert code == 0, output
    run = only_run(tmp_path / "runs")
    code, output = main("--resume", run, "--generations", 4)
    assert code == 0, output
    return run


def expected_rows(run: Path) -> dict[int, dict[str, float]]:
    """generation -> its metrics.csv row's numeric, finite columns."""
    found = {}
    for row in read_metrics(run / "metrics.csv"):
        values = {name: float(row[name]) for name in METRICS_COLUMNS[1:] if row[name] not in ("", None)}
        found[int(row["generation"])] = {name: value for name, value in values.items() if math.isfinite(value)}
    return found


# --- W&B ------------------------------------------------------------------------------------------------


def wandb_records(run: Path) -> list[list[dict]]:
    """The records of each offline W&B run folder of the run, in order, as W&B's own reader prints them."""
    runs = []
    for folder in sorted((run / "wandb").glob("offline-run-*")):
        (log,) = folder.glob("run-*.wandb")
        result = subprocess.run([sys.executable, "-m", "wandb", "leet", "inspect", "--json", str(log)],
                                capture_output=True, text=True, timeout=120, cwd=run)
        assert result.returncode == 0, result.stderr
        runs.append([json.loads(line) for line in result.stdout.splitlines() if line.strip()])
    return runs


def test_wandb_offline_holds_metrics_csv_once_and_continues_its_run_on_resume(tmp_path, monkeypatch):
    need("wandb")
    run = split_run(tmp_path, "wandb", monkeypatch=monkeypatch)
    config = json.loads((run / "config.json").read_text())
    run_id = config["log"]["wandb_run_id"]
    processes = wandb_records(run)
    assert len(processes) == 2  # the run and its resume, each its own offline folder of the same W&B run
    history = {}
    for records in processes:
        (started,) = [record["run"] for record in records if record["type"] == "run"]
        assert started["run_id"] == run_id and started["project"] == "hebbian-es"
        settings = {}
        for record in records:
            if record["type"] in ("run", "config"):
                settings.update(record[record["type"]].get("config", record[record["type"]]).get("update", {}))
        assert settings["es"]["popsize"] == 4 and settings["log"]["logger"] == ["wandb"]  # config.json's settings
        for record in records:
            if record["type"] == "history":
                step = record["history"]["step"]["num"]
                assert step not in history, f"generation {step} sent twice"
                history[step] = record["history"]["item"]
    expected = expected_rows(run)
    assert sorted(history) == sorted(expected) == [1, 2, 3, 4]
    for step, values in expected.items():
        for name, value in values.items():
            assert history[step][name] == pytest.approx(value, rel=1e-12), (step, name)
    for records in processes:  # each process ran its generations to the end: the files as they were then
        artifacts = {record["artifact"]["name"]: {entry["path"] for entry in record["artifact"]["manifest"]["contents"]}
                     for record in records if record["type"] == "artifact"}
        assert artifacts == {f"figures-{run_id}": {"fitness.png"}, f"weights-{run_id}": {"best.dat", "last.dat"}}


# --- MLflow -----------------------------------------------------------------------------------------------


def mlflow_client(run: Path):
    from mlflow.tracking import MlflowClient

    return MlflowClient(tracking_uri=f"sqlite:///{run / 'mlflow' / 'mlflow.db'}")


def mlflow_history(client, run_id: str) -> dict[int, dict[str, float]]:
    """generation -> metric -> value; a step held twice fails."""
    found: dict[int, dict[str, float]] = {}
    for name in client.get_run(run_id).data.metrics:
        for metric in client.get_metric_history(run_id, name):
            assert name not in found.setdefault(metric.step, {}), f"{name} at generation {metric.step} twice"
            found[metric.step][name] = metric.value
    return found


def test_mlflow_store_holds_metrics_csv_once_and_continues_its_run_on_resume(tmp_path, monkeypatch):
    need("mlflow")
    run = split_run(tmp_path, "mlflow", monkeypatch=monkeypatch)
    run_id = json.loads((run / "config.json").read_text())["log"]["mlflow_run_id"]
    client = mlflow_client(run)
    assert [found.info.run_id for found in client.search_runs(
        [client.get_experiment_by_name("hebbian-es").experiment_id])] == [run_id]  # one run, continued
    assert mlflow_history(client, run_id) == expected_rows(run)
    logged = client.get_run(run_id)
    assert logged.info.status == "FINISHED"
    assert logged.data.params["es.popsize"] == "4" and logged.data.params["policy.kind"] == "static"
    assert logged.data.params["run.generations"] == "2"  # MLflow keeps a parameter's first value
    assert {item.path for item in client.list_artifacts(run_id, "weights")} == {"weights/best.dat", "weights/last.dat"}
    assert {item.path for item in client.list_artifacts(run_id, "figures")} == {"figures/fitness.png"}
    saved = Path(client.download_artifacts(run_id, "config.json", str(tmp_path)))
    assert json.loads(saved.read_text())["run"]["generations"] == 4  # config.json as the resume rewrote it


def test_mlflow_does_not_take_again_the_generations_it_holds_past_the_checkpoint(tmp_path, monkeypatch):
    """A run stopped after sending generations its checkpoint does not hold (killed between two saves) redoes
    them on resume; the MLflow run keeps the values it has and gets no second one."""
    need("mlflow")
    for name in ("MLFLOW_TRACKING_URI",):
        monkeypatch.delenv(name, raising=False)
    code, output = main(*CARTPOLE, "--generations", 2, "--folder", tmp_path / "runs", "--logger", "mlflow")
    assert code == 0, output
    run = only_run(tmp_path / "runs")
    at_two = tmp_path / "at_two"
    shutil.copytree(run, at_two, ignore=shutil.ignore_patterns("mlflow", ".lock"))
    code, output = main("--resume", run, "--generations", 4)
    assert code == 0, output
    sent = mlflow_history(mlflow_client(run), json.loads((run / "config.json").read_text())["log"]["mlflow_run_id"])
    for name in ("checkpoint.npz", "metrics.csv", "config.json"):  # the run as its checkpoint of generation 2 left it
        shutil.copy(at_two / name, run / name)
    code, output = main("--resume", run, "--generations", 4)
    assert code == 0, output
    run_id = json.loads((run / "config.json").read_text())["log"]["mlflow_run_id"]
    held = mlflow_history(mlflow_client(run), run_id)
    assert sorted(held) == [1, 2, 3, 4] and held == sent


# --- refusals, in one line ----------------------------------------------------------------------------------


@pytest.mark.parametrize("name, packages, extra", [("wandb", ("wandb",), "wandb"),
                                                    ("mlflow", ("mlflow", "sqlalchemy", "alembic"), "mlflow"),
                                                    ("tensorboard", ("tensorboard",), "tensorboard")])
def test_a_logger_without_its_package_says_how_to_install_it(name, packages, extra, tmp_path, monkeypatch):
    for package in packages:  # as if none of them were installed: the same message with or without the extra
        monkeypatch.setitem(sys.modules, package, None)
    code, output = main(*CARTPOLE, "--generations", 1, "--folder", tmp_path / "runs", "--logger", name)
    assert code == 2 and len(output.strip().splitlines()) == 1, output
    needs = (f"the {packages[0]} package, which is not installed; install it" if len(packages) == 1 else
             f"the {', '.join(packages)} packages, which are not installed; install them")
    assert output.strip() == (f"train_static.py: error: --logger {name} needs {needs} with: pip install -r "
                              f"requirements-{extra}.txt (or pip install -e .[{extra}])")
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize("argv, message", [
    (("--logger", "neptune"), "argument --logger: invalid choice: 'neptune'"),
    (("--wandb_project", "x"), "--wandb_project has an effect only with --logger wandb"),
    (("--logger", "tensorboard", "--mlflow_uri", "sqlite:///x.db"), "--mlflow_uri has an effect only with --logger "
                                                                      "mlflow"),
])
def test_logger_flags_are_checked_in_one_line(argv, message, tmp_path):
    code, output = main(*CARTPOLE, "--generations", 1, "--folder", tmp_path / "runs", *argv)
    assert code == 2 and len(output.strip().splitlines()) == 1 and message in output, output
    assert not (tmp_path / "runs").exists()


def test_an_mlflow_run_missing_from_the_store_is_refused_in_one_line(tmp_path, monkeypatch):
    need("mlflow")
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    code, output = main(*CARTPOLE, "--generations", 1, "--folder", tmp_path / "runs", "--logger", "mlflow")
    assert code == 0, output
    run = only_run(tmp_path / "runs")
    other = f"sqlite:///{tmp_path / 'other.db'}"
    code, output = main("--resume", run, "--generations", 2, "--mlflow_uri", other)
    run_id = json.loads((run / "config.json").read_text())["log"]["mlflow_run_id"]
    assert code == 2 and output.strip().splitlines()[-1] == (
        f"train_static.py: error: --logger mlflow: the MLflow run {run_id} that config.json records is not in {other}; "
        "give --mlflow_uri the store it was logged to"), output


# --- a tracker that cannot be reached or written: one line, within a bound, no run folder left -------------


def closed_port() -> int:
    """A local port nothing listens on (one the system just gave and took back)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def train_process(*argv, env: dict | None = None, timeout: float = 60) -> subprocess.CompletedProcess:
    """train_static.py as a process that must end within ``timeout`` seconds (the trackers' own retries take
    minutes; the bound the tool states is 5 s of waiting, this one is loose for a loaded machine)."""
    environ = {key: value for key, value in os.environ.items() if not key.startswith(("WANDB_", "MLFLOW_"))}
    return subprocess.run([sys.executable, str(ROOT / "train_static.py"), *map(str, argv)], cwd=ROOT,
                          env={**environ, "SDL_VIDEODRIVER": "dummy", "NETRC": os.devnull, **(env or {})},
                          capture_output=True, text=True, timeout=timeout)


def unwritable_database(tmp_path: Path) -> str:
    """A SQLite URI no file can be created at, whoever runs the test (root too): a folder of /sys."""
    return "sqlite:////sys/mlflow.db" if Path("/sys").is_dir() else f"sqlite:///{tmp_path / 'a file' / 'mlflow.db'}"


@pytest.mark.parametrize("store, problem", [
    (lambda tmp_path: f"http://127.0.0.1:{closed_port()}", "nothing answers there"),
    (lambda tmp_path: f"http://user:secret@127.0.0.1:{closed_port()}", "nothing answers there"),
    (unwritable_database, "the database cannot be opened"),
])
def test_an_mlflow_store_that_cannot_be_reached_or_written_fails_at_once_in_one_line(tmp_path, store, problem):
    need("mlflow")
    (tmp_path / "a file").write_text("")
    uri = store(tmp_path)
    done = train_process(*CARTPOLE, "--generations", 1, "--folder", tmp_path / "runs", "--logger", "mlflow",
                         "--mlflow_uri", uri)
    (line,) = done.stderr.strip().splitlines()
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert line.startswith(f"train_static.py: error: --logger mlflow: --mlflow_uri {uri.replace('secret', '***')}: "
                           f"{problem}"), line
    assert "secret" not in line
    assert not (tmp_path / "runs").exists()  # the run never started: no folder left behind


def test_a_wandb_server_that_does_not_answer_fails_at_once_in_one_line(tmp_path):
    need("wandb")
    base = f"http://127.0.0.1:{closed_port()}"
    done = train_process(*CARTPOLE, "--generations", 1, "--folder", tmp_path / "runs", "--logger", "wandb",
                         env={"WANDB_MODE": "online", "WANDB_API_KEY": "0" * 40, "WANDB_BASE_URL": base})
    assert done.returncode == 2 and done.stderr.strip() == (
        f"train_static.py: error: --logger wandb: the W&B server {base} (WANDB_BASE_URL) does not answer (Connection "
        "refused); log offline with WANDB_MODE=offline, or give the address of a server that runs"), done.stderr
    assert not (tmp_path / "runs").exists()


def test_a_resume_whose_tracker_cannot_be_reached_changes_nothing(tmp_path, monkeypatch):
    need("mlflow")
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    code, output = main(*CARTPOLE, "--generations", 1, "--folder", tmp_path / "runs")
    assert code == 0, output
    run = only_run(tmp_path / "runs")
    before = {path.name: path.read_bytes() for path in run.iterdir() if path.is_file()}
    uri = f"http://127.0.0.1:{closed_port()}"
    done = train_process("--resume", run, "--generations", 2, "--logger", "mlflow", "--mlflow_uri", uri)
    assert done.returncode == 2 and done.stderr.strip() == (
        f"train_static.py: error: --logger mlflow: --mlflow_uri {uri}: nothing answers there (Connection refused); "
        "start the tracking server, or give the URI of one that runs"), done.stderr
    assert {path.name: path.read_bytes() for path in run.iterdir() if path.is_file()} == before
