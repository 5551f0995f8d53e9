"""A benchmark's record: what one run measured, on which machine, at which load (benchmarks/results/*.json).

Every script of ``benchmarks/`` writes one record per run through this module, and ``docs/generate.py``
renders the figures of the README and ``docs/`` from records, never from numbers typed into a page.
A record holds the commit, the date, the CPU model and cores, the versions of the packages that set the
speed, the 1-minute load average before and after the run, the command, and for each measure its value in
every round with their median, minimum and maximum. A record taken while the load average exceeded the
number of cores, before or after the run, is marked ``loaded``: the machine was shared, and the docs
refuse to publish it (docs/development.md, "Benchmark discipline"). A record of counts that no load can move
(environment steps to solve a task, from seeded runs) is made with ``timed=False``: it keeps its load, and is
never marked loaded.

Beside its measures a record keeps notes: results that are not figures, and tables (``table``), which
``docs/generate.py`` renders as they are, their cells text, numbers or ``{"value", "low", "high"}`` estimates
with their intervals.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import os
import platform
import re
import shlex
import statistics
import subprocess
import sys
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # the project's modules, for a benchmark run as a script
    sys.path.insert(0, str(ROOT))

from cli.errors import UserError  # noqa: E402
from cli.train import check_writable  # noqa: E402
from report.machine import cpu_model  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
# what sets the speed of every benchmark: the interpreter is added, and each script names its own extras
VERSIONS = ("numpy", "numba", "torch", "gymnasium", "box2d", "pygame-ce", "mujoco", "pybullet",
            "opencv-python-headless")
MIN_ROUNDS = 5  # a published figure is the median of at least this many rounds


@dataclass
class Measure:
    """One measured quantity: its value in each round, in ``unit`` (``x`` for a ratio of speeds, ``""``
    for a plain ratio, ``us``, ``ms``, ``s``, ``h``, ``MiB``, ``steps/s``)."""
    what: str
    unit: str
    values: list[float]
    median: float = field(init=False)
    min: float = field(init=False)
    max: float = field(init=False)
    rounds: int = field(init=False)

    def __post_init__(self):
        self.values = [float(value) for value in self.values]
        if not self.values:
            raise ValueError(f"{self.what}: a measure needs at least one value")
        self.median, self.min, self.max = statistics.median(self.values), min(self.values), max(self.values)
        self.rounds = len(self.values)


def documented_parser(doc: str) -> argparse.ArgumentParser:
    """A benchmark's parser, its description and epilog its module's docstring (first line, then the rest)."""
    return argparse.ArgumentParser(description=doc.splitlines()[0], epilog="\n".join(doc.splitlines()[2:]),
                                   formatter_class=argparse.RawDescriptionHelpFormatter)


def writable_folder(text: str) -> Path:
    """A folder a record can be written into (made where it is missing), checked before the benchmark runs."""
    try:
        check_writable(text)
    except UserError:
        raise argparse.ArgumentTypeError(f"{text} is not a writable folder, nor one that can be made there") from None
    return Path(text)


def add_results_flag(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--results", type=writable_folder, default=RESULTS, metavar="FOLDER",
                        help="where the run's JSON record is written (default: benchmarks/results)")


def commit() -> str:
    """The checkout's commit, ``+changes`` when tracked files differ from it; ``unknown`` outside git."""
    def git(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True)
    try:
        head = git("rev-parse", "--short=12", "HEAD")
        if head.returncode:
            return "unknown"
        return head.stdout.strip() + ("+changes" if git("diff", "--quiet", "HEAD").returncode else "")
    except OSError:
        return "unknown"


def versions(extra: tuple[str, ...] = ()) -> dict[str, str]:
    found = {"python": platform.python_version()}
    for name in (*VERSIONS, *extra):
        try:
            found[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            found[name] = "not installed"
    return found


def load() -> float:
    return os.getloadavg()[0]


class Record:
    """The record of one run of a benchmark script. Made at the start of the run (the load before it),
    given measures as they are taken, written at the end (the load after it)."""

    def __init__(self, name: str, extra_versions: tuple[str, ...] = (), timed: bool = True):
        script = Path(sys.argv[0]).resolve()
        shown = script.relative_to(ROOT) if script.is_relative_to(ROOT) else script
        self.name = re.sub(r"[^A-Za-z0-9_.-]+", "_", name)
        self.started = datetime.now(UTC)
        self.fields = {"command": shlex.join(["python", str(shown), *sys.argv[1:]]), "commit": commit(),
                       "date": self.started.isoformat(timespec="seconds"), "cpu": cpu_model(),
                       "cores": os.cpu_count(), "versions": versions(extra_versions), "load_before": load(),
                       "timed": timed}
        self.measures: dict[str, Measure] = {}
        self.notes: dict[str, object] = {}

    def add(self, key: str, what: str, unit: str, values) -> Measure:
        if key in self.measures:
            raise ValueError(f"{key}: measured twice in one record")
        self.measures[key] = Measure(what, unit, list(values))
        return self.measures[key]

    def note(self, key: str, value) -> None:
        """A result that is not a figure (an identity check, the largest difference found)."""
        self.notes[key] = value

    def table(self, key: str, columns: list[str], rows: list[list]) -> None:
        """A table for the docs (``<!-- table:RECORD KEY -->``): each cell text, a number, or an estimate
        ``{"value": v, "low": l, "high": h}`` with its interval."""
        if any(len(row) != len(columns) for row in rows):
            raise ValueError(f"{key}: every row needs {len(columns)} cells ({', '.join(columns)})")
        self.notes[key] = {"columns": list(columns), "rows": [list(row) for row in rows]}

    def write(self, folder: Path) -> Path:
        after = load()
        cores = self.fields["cores"]
        loaded = self.fields["timed"] and max(self.fields["load_before"], after) > cores
        body = {**self.fields, "load_after": after, "loaded": loaded,
                "measures": {key: asdict(measure) for key, measure in self.measures.items()}, "notes": self.notes}
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{self.name}-{self.started:%Y%m%dT%H%M%SZ}.json"
        path.write_text(json.dumps(body, indent=1) + "\n")
        shown = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
        state = (f"LOADED: load average {max(self.fields['load_before'], after):.2f} on {cores} cores, not "
                 "publishable" if loaded else f"load average {self.fields['load_before']:.2f} -> {after:.2f} on "
                 f"{cores} cores" + ("" if self.fields["timed"] else "; counts, not timed: no load moves them"))
        short = [key for key, measure in self.measures.items() if measure.rounds < MIN_ROUNDS]
        if short:
            state += (f"; {', '.join(short) if len(short) < 4 else f'{len(short)} measures'} of fewer than "
                      f"{MIN_ROUNDS} rounds, not publishable")
        print(f"record: {shown} ({state})")
        return path


def read(path: Path) -> dict:
    """A record as written, its measures as dicts; ValueError naming the file if it is not one."""
    try:
        record = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as error:
        raise ValueError(f"{path}: not a benchmark record ({error})") from error
    missing = {"command", "commit", "date", "cpu", "cores", "versions", "load_before", "load_after", "loaded",
               "measures"} - set(record)
    if missing:
        raise ValueError(f"{path}: not a benchmark record (no {', '.join(sorted(missing))})")
    return record


STAMPED = re.compile(r"-\d{8}T\d{6}Z\.json$")  # a record's file name: its command's name, then when it was taken


def newest(name: str, results: Path = RESULTS, holds=lambda record: True) -> tuple[Path, dict]:
    """The newest record of the command ``name`` (``results/<name>-<time>.json``) not taken on a loaded machine that
    ``holds`` what is asked of it (a measure some runs of the command add, such as ``--memory``'s), and its path;
    ValueError where there is none. A page names the command, never one record: a new record of it renders
    everywhere the figure appears."""
    import glob

    stamped = sorted(path for path in results.glob(f"{glob.escape(name)}-*.json")
                     if STAMPED.search(path.name) and path.name[:len(name)] == name
                     and not STAMPED.sub("", path.name[len(name):]))
    where = results.relative_to(ROOT) if results.is_relative_to(ROOT) else results
    if not stamped:
        raise ValueError(f"{name}: no record {where}/{name}-<time>.json")
    quiet = False
    for path in reversed(stamped):
        record = read(path)
        quiet = quiet or not record["loaded"]
        if not record["loaded"] and holds(record):
            return path, record
    if quiet:
        raise LookupError(f"{name}: no record of it taken on a quiet machine holds what is asked")
    raise ValueError(f"{name}: every record was taken on a loaded machine (the newest at load "
                     f"{max(record['load_before'], record['load_after']):.2f} on {record['cores']} cores); "
                     "measure again on a quiet machine")
