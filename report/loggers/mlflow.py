"""``--logger mlflow``: the run in MLflow (``requirements-mlflow.txt``: MLflow's client, and SQLAlchemy
for a database store).

The tracking store is ``--mlflow_uri``, else ``MLFLOW_TRACKING_URI``, else a SQLite database in the run
folder (``<run folder>/mlflow/mlflow.db``, its artifacts beside it): MLflow 3 keeps its file store only in
maintenance mode and refuses it unless told otherwise, so a local run goes to a database. View it with
``mlflow ui --backend-store-uri sqlite:///<run folder>/mlflow/mlflow.db``.

The MLflow run, in experiment ``--mlflow_experiment``, gets the run's settings as parameters (``es.lr``,
``policy.hebb_rule``, ...), config.json itself as an artifact and the command as a tag; each metrics row is
one batch of metrics at its generation; the figures and final weight files are artifacts under
``figures/`` and ``weights/``. Its id is recorded in config.json (``log.mlflow_run_id``): a resumed run
continues it, sending none of the generations it already holds, and adds the parameters it lacks (MLflow
keeps a parameter's first value: a resumable setting changed by the resume, such as ``run.generations``,
stays as first logged there; config.json, logged again, has the new value).

A store that cannot be reached or written stops the run's start within ``REACH_SECONDS`` (``check_store``),
in one line naming its URI: MLflow itself retries a server for minutes and a database for over a minute. As
the run starts, each request to a server waits ``REACH_SECONDS`` at most and is not retried (unless
``MLFLOW_HTTP_REQUEST_TIMEOUT`` or ``MLFLOW_HTTP_REQUEST_MAX_RETRIES`` say otherwise); later, while it
trains, MLflow's own retries apply, and a store lost for good drops the logger with a warning.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit, urlunsplit

from report.loggers.base import GROUP, REACH_SECONDS, LoggerPlugin, unreachable
from settings import setting

SECTIONS = ("es", "policy", "env", "run", "log")  # config.json's settings, logged as parameters
STEP_KEY = "total_env_steps"  # a column every row has, finite: which steps the MLflow run holds
BATCH = 100  # parameters per request (MLflow's limit)
PORTS = {"http": 80, "https": 443, "postgresql": 5432, "mysql": 3306, "mssql": 1433}  # the stores MLflow reaches
# over the network, and their default ports


@dataclass(frozen=True)
class MLflowSettings:
    mlflow_uri: str | None = setting(None, nonempty=True, resumable=True, group=GROUP,
                                     metavar="URI", shown_default="MLFLOW_TRACKING_URI, else sqlite:///<run>/mlflow/"
                                                                  "mlflow.db",
                                     help="the MLflow tracking store (a server's http URI, a database's)")
    mlflow_experiment: str = setting("hebbian-es", nonempty=True, resumable=True, group=GROUP,
                                     metavar="NAME", help="the MLflow experiment of the run")
    mlflow_run_id: str | None = setting(None, flag=None, derived=True,
                                        help="the MLflow run's id, made at the run's start (a resume continues it)")


def shown(uri: str) -> str:
    """A URI as messages show it: a password in it replaced by ***."""
    parts = urlsplit(uri)
    if not parts.password:
        return uri
    return urlunsplit(parts._replace(netloc=parts.netloc.replace(f":{parts.password}@", ":***@", 1)))


class StoreError(ValueError):
    """The tracking store cannot be used: one line naming it."""


def check_store(uri: str, given_as: str) -> None:
    """Refuse, within ``REACH_SECONDS`` and in one line naming the URI (``given_as``: the flag or variable that
    gave it), a tracking store that nothing answers at, or a SQLite database that cannot be opened."""
    parts = urlsplit(uri)
    scheme = parts.scheme.partition("+")[0]  # postgresql+psycopg2: the database, then its driver
    if scheme == "sqlite":
        database = uri.partition(":///")[2].partition("?")[0]  # sqlite:///relative.db, sqlite:////absolute.db
        if not database or database == ":memory:":
            return
        folder = Path(database).parent
        existing = next((parent for parent in (folder, *folder.parents) if parent.exists()), Path("."))
        try:
            if not existing.is_dir():  # MLflow makes the folders that are missing, under a folder
                raise sqlite3.OperationalError(f"{existing} is not a folder")
            if folder.is_dir():
                with contextlib.closing(sqlite3.connect(database, timeout=REACH_SECONDS)) as connection:
                    connection.execute("PRAGMA schema_version")  # opens (or creates) the file, reads its header
        except sqlite3.Error as error:
            raise StoreError(f"{given_as} {shown(uri)}: the database cannot be opened ({error}); give a SQLite "
                             "file in a writable folder, or a tracking server's http URI") from None
    elif scheme in PORTS and parts.netloc:
        reason = unreachable(uri, PORTS[scheme])
        if reason is not None:
            raise StoreError(f"{given_as} {shown(uri)}: nothing answers there ({reason}); start the tracking "
                             "server, or give the URI of one that runs")


@contextlib.contextmanager
def bounded_requests():
    """MLflow's requests to a server, each waiting ``REACH_SECONDS`` at most and not retried, unless the user's
    environment says otherwise: as the run starts, a server that does not answer stops it at once."""
    bounds = {"MLFLOW_HTTP_REQUEST_TIMEOUT": str(REACH_SECONDS), "MLFLOW_HTTP_REQUEST_MAX_RETRIES": "0"}
    mine = {name: value for name, value in bounds.items() if name not in os.environ}
    os.environ.update(mine)
    try:
        yield
    finally:
        for name in mine:
            os.environ.pop(name, None)


def parameters(record: dict) -> dict[str, str]:
    """config.json's settings, flat: ``{"es.lr": "0.2", ...}``."""
    return {f"{section}.{key}": str(value) for section in SECTIONS for key, value in record.get(section, {}).items()}


class MLflowLogger:
    def __init__(self, settings: MLflowSettings, run_folder: Path, say=print):
        self.settings, self.folder = settings, Path(run_folder)
        self.client = self.run_id = None
        self.held = 0  # the last generation the MLflow run holds

    def store(self) -> tuple[str, str | None]:
        """The tracking URI, and where a new experiment of the run folder's own database keeps its artifacts.
        A store given (flag or variable) is checked first (``check_store``)."""
        for given_as, given in (("--mlflow_uri", self.settings.mlflow_uri),
                                ("MLFLOW_TRACKING_URI", os.environ.get("MLFLOW_TRACKING_URI"))):
            if given:
                check_store(given, given_as)
                return given, None
        local = (self.folder / "mlflow").resolve()
        local.mkdir(exist_ok=True)
        return f"sqlite:///{local / 'mlflow.db'}", (local / "artifacts").as_uri()

    def begin(self, record: dict, generation: int) -> dict:
        for name in ("mlflow", "alembic"):  # their notes on creating the database: the run's output stays ours
            logging.getLogger(name).setLevel(logging.WARNING)
        uri, artifacts = self.store()
        try:
            with bounded_requests():
                return self._begin(record, uri, artifacts)
        except StoreError:
            raise
        except Exception as error:  # MLflow's: the server's answer, a database that cannot be written
            first = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
            raise StoreError(f"the tracking store {shown(uri)} failed as the run started: {first}") from None

    def _begin(self, record: dict, uri: str, artifacts: str | None) -> dict:
        from mlflow.entities import Param
        from mlflow.exceptions import MlflowException
        from mlflow.tracking import MlflowClient

        self.client = MlflowClient(tracking_uri=uri)
        known = {}
        if self.settings.mlflow_run_id is not None:
            try:
                run = self.client.get_run(self.settings.mlflow_run_id)
            except MlflowException:
                raise StoreError(f"the MLflow run {self.settings.mlflow_run_id} that config.json records is not in "
                                 f"{uri}; give --mlflow_uri the store it was logged to") from None
            self.run_id, known = run.info.run_id, run.data.params
            self.held = max((metric.step for metric in self.client.get_metric_history(self.run_id, STEP_KEY)),
                            default=0)
            self.client.update_run(self.run_id, status="RUNNING")
        else:
            name = self.settings.mlflow_experiment
            experiment = self.client.get_experiment_by_name(name)
            experiment_id = (experiment.experiment_id if experiment is not None else
                             self.client.create_experiment(name, artifact_location=artifacts))
            self.run_id = self.client.create_run(experiment_id, run_name=self.folder.name,
                                                 tags={"command": str(record.get("command", ""))}).info.run_id
        new = [Param(key, value) for key, value in parameters(record).items() if key not in known]
        for start in range(0, len(new), BATCH):
            self.client.log_batch(self.run_id, params=new[start:start + BATCH])
        self.client.log_dict(self.run_id, record, "config.json")
        return {"mlflow_run_id": self.run_id}

    def log(self, step: int, values: dict[str, float]) -> None:
        if step <= self.held:
            return
        from mlflow.entities import Metric

        now = int(time.time() * 1000)
        self.client.log_batch(self.run_id, metrics=[Metric(key, value, now, step) for key, value in values.items()])

    def flush(self) -> None:
        pass

    def artefacts(self, figures: list[Path], weights: list[Path]) -> None:
        for kind, paths in (("figures", figures), ("weights", weights)):
            for path in paths:
                self.client.log_artifact(self.run_id, str(path), kind)

    def close(self, finished: bool) -> None:
        if self.run_id is not None:
            self.client.set_terminated(self.run_id, "FINISHED" if finished else "KILLED")


PLUGIN = LoggerPlugin("mlflow", about="MLflow, in MLFLOW_TRACKING_URI / --mlflow_uri or a SQLite database in the "
                                       "run folder", settings=MLflowSettings, make=MLflowLogger,
                      modules=("mlflow", "sqlalchemy", "alembic"), extra="mlflow")
