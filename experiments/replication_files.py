"""The campaign's files as the replication report reads them (experiments/replication.py): each kind's line of an
experiment's report, and the evaluated runs, each file named where it cannot be read."""

from __future__ import annotations

import csv
import json
import re
from dataclasses import dataclass
from pathlib import Path

EVALUATION, MADE_WITH = "evaluation.json", "made_with.json"


class ReplicationError(ValueError):
    """A file of the campaign that cannot be read as a run or a report; names it."""


def read_csv(path: Path) -> list[dict]:
    try:
        with path.open(newline="") as handle:
            return list(csv.DictReader(handle))
    except (OSError, csv.Error, UnicodeDecodeError) as error:
        raise ReplicationError(f"{path}: unreadable ({error})") from None


def read_json(path: Path) -> dict:
    try:
        value = json.loads(path.read_text())
    except (OSError, ValueError) as error:
        raise ReplicationError(f"{path}: unreadable ({error})") from None
    if not isinstance(value, dict):
        raise ReplicationError(f"{path}: not a JSON object")
    return value


@dataclass(frozen=True)
class Group:
    """One kind's line of a report's summary.csv."""
    kind: str
    runs: int
    iqm: tuple[float, float, float]  # estimate, low, high
    mean: tuple[float, float, float]


@dataclass(frozen=True)
class Report:
    folder: Path
    groups: dict[str, Group]
    better: dict[tuple[str, str], tuple[float, float, float]]  # (X, Y) -> P(X > Y), low, high


def read_report(runs: Path, experiment: str, environment: str) -> Report | None:
    """The campaign's report of ``experiment`` on ``environment``; None where there is none yet."""
    folder = runs / f"{experiment}_report" / environment
    if not (folder / "summary.csv").is_file():
        return None
    try:
        groups = {row["group"]: Group(row["group"], int(row["runs"]),
                                      tuple(float(row[key]) for key in ("iqm", "iqm_low", "iqm_high")),
                                      tuple(float(row[key]) for key in ("mean", "mean_low", "mean_high")))
                  for row in read_csv(folder / "summary.csv")}
        better = {(row["x"], row["y"]): tuple(float(row[key]) for key in ("probability", "low", "high"))
                  for row in read_csv(folder / "improvement.csv")}
    except (KeyError, ValueError) as error:
        raise ReplicationError(f"{folder}: not a report of the campaign ({type(error).__name__}: {error})") from None
    return Report(folder, groups, better)


@dataclass(frozen=True)
class Run:
    """An evaluated run of the campaign: the newest run folder of ``results/paper/<experiment>_<kind>_seed<N>``."""
    name: str  # the seed folder's: ant_hebbian_seed1
    folder: Path
    experiment: str
    kind: str
    seed: int
    config: dict
    evaluation: dict
    made_with: dict | None

    def metrics(self) -> list[dict]:
        return read_csv(self.folder / "metrics.csv")


SEED_FOLDER = re.compile(r"(?P<experiment>[a-z0-9]+)_(?P<kind>static|hebbian)_seed(?P<seed>\d+)")


def evaluated_runs(runs: Path) -> list[Run]:
    """The campaign's evaluated runs, by experiment, kind and seed."""
    found = []
    for seed_folder in sorted(runs.iterdir()) if runs.is_dir() else []:
        match = SEED_FOLDER.fullmatch(seed_folder.name)
        if not match or not seed_folder.is_dir():
            continue
        candidates = sorted(path for path in seed_folder.iterdir() if (path / "config.json").is_file())
        if not candidates or not (candidates[-1] / EVALUATION).is_file():
            continue
        folder = candidates[-1]
        made_with = read_json(folder / MADE_WITH) if (folder / MADE_WITH).is_file() else None
        found.append(Run(seed_folder.name, folder, match["experiment"], match["kind"], int(match["seed"]),
                         read_json(folder / "config.json"), read_json(folder / EVALUATION), made_with))
    return sorted(found, key=lambda run: (run.experiment, run.kind != "hebbian", run.seed))


def hours(run: Run) -> tuple[float, int, int]:
    """Training time (hours of wall clock), environment steps and generations, from metrics.csv."""
    rows = run.metrics()
    try:
        return (sum(float(row["seconds"]) for row in rows) / 3600, sum(int(row["env_steps"]) for row in rows),
                len(rows))
    except (KeyError, ValueError) as error:
        raise ReplicationError(f"{run.folder / 'metrics.csv'}: unreadable ({type(error).__name__}: {error})") from None
