"""What a logger is (``--logger``, ``report.loggers``): one module that sends a run to an experiment
tracker, and declares to the registry how it is made, what it needs installed and its own settings.

A logger (``Logger``) receives, in this order:

- ``begin(record, generation)``: the run's settings once, as config.json records them (the sections,
  the command, the versions, the parameter count), when the run starts (generation 0) or resumes after
  its checkpoint's generation; it returns what config.json should record of it, such as its tracker's
  run id, so that a resumed run continues the same tracker run;
- ``log(step, values)``: every row that goes to metrics.csv, its numeric, finite columns (``scalars``),
  with the generation as the step. A resumed run recomputes only the generations after its checkpoint,
  and a logger that finds its tracker already holding one of them (a run stopped between two saves)
  sends it no second time;
- ``flush()`` at every save of the run's files;
- ``artefacts(figures, weights)`` once the run has run all its generations: its figures (``fitness.png``)
  and its final weight files (``last*`` and ``best*``: the .dat files and observation statistics);
- ``close(finished)`` when the process ends, finished or not.

Its plug-in (``LoggerPlugin``, ``plugins``): its name, what it is, its settings (a frozen dataclass of its own
fields made with ``settings.setting()``: each then has an effect only with ``--logger <its name>``, and
config.json records it only then), the factory, the modules it imports (checked before anything starts: a
missing one is refused in one line with its install command) and the extra that installs them
(``requirements-<extra>.txt``), required with them.
"""

from __future__ import annotations

import importlib.util
import math
import socket
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol
from urllib.parse import urlsplit

from es.files import METRICS_COLUMNS
from plugins import Plugin

GROUP = "experiment trackers (--logger)"  # --help's group of the loggers' flags
REACH_SECONDS = 5  # the longest a tracker may take to answer as the run starts (docs/flags.md)


class Logger(Protocol):
    def begin(self, record: dict, generation: int) -> dict:
        """The run's settings, once; what config.json records of this logger."""

    def log(self, step: int, values: dict[str, float]) -> None:
        """One metrics row's numeric values at its generation."""

    def flush(self) -> None:
        """At every save of the run's files."""

    def artefacts(self, figures: list[Path], weights: list[Path]) -> None:
        """The run's figures and final weight files, when it has run all its generations."""

    def close(self, finished: bool) -> None:
        """When the process ends; ``finished``: the run has run all its generations."""


@dataclass(frozen=True, kw_only=True)
class LoggerPlugin(Plugin):
    """A logger as its module declares it (``plugins.Plugin``: its name, what it is, its settings)."""

    make: Callable[..., Logger]  # (the run's LogSettings, its folder, the run's say) -> the logger
    modules: tuple[str, ...] = ()  # what it imports beside the project's requirements
    extra: str = ""  # what installs them (required with them): requirements-<extra>.txt, pyproject.toml's [<extra>]

    def __post_init__(self) -> None:
        if self.modules and not self.extra:
            raise ValueError(f"logger {self.name!r} imports {', '.join(self.modules)}: name the extra that installs "
                             "them (extra=...)")

    @property
    def install_hint(self) -> str:
        return f"pip install -r requirements-{self.extra}.txt (or pip install -e .[{self.extra}])"

    def missing(self) -> list[str]:
        return [module for module in self.modules if importlib.util.find_spec(module) is None]


def scalars(row: dict, extra_columns: tuple[str, ...] = ()) -> dict[str, float]:
    """The row's numeric, finite columns, but the step itself; ``extra_columns``: the policy kind's."""
    found = {}
    for name in METRICS_COLUMNS[1:] + tuple(extra_columns):
        try:
            value = float(row.get(name))
        except (TypeError, ValueError):  # absent, empty or not a number
            continue
        if math.isfinite(value):
            found[name] = value
    return found


def unreachable(url: str, default_port: int) -> str | None:
    """Why nothing answers at ``url``'s host and port within ``REACH_SECONDS`` (a TCP connection), or None if
    something does: a tracker's own client retries an unreachable server for minutes before it says so."""
    parts = urlsplit(url)
    try:
        port = parts.port or default_port
    except ValueError:  # Python's words for a port out of range or not a number
        return "its port is not a whole number from 1 to 65535"
    if not parts.hostname:
        return "it names no host"
    try:
        socket.create_connection((parts.hostname, port), timeout=REACH_SECONDS).close()
    except TimeoutError:
        return f"no answer within {REACH_SECONDS} s"
    except OSError as error:
        return error.strerror or str(error)
    return None
