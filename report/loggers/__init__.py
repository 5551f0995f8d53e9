"""The run's experiment trackers (``--logger``): the registry of loggers, their settings, and ``Loggers``, which
drives the chosen ones for the training script (``cli.train``: it makes them, hands them each generation's row
as the loop gives it, and closes them).

    tensorboard  TensorBoard scalars in <run>/tensorboard (``--tensorboard`` is the same as --logger tensorboard)
    wandb        Weights & Biases, offline where no login is configured
    mlflow       MLflow, in MLFLOW_TRACKING_URI / --mlflow_uri or a SQLite database in the run folder

A logger is one module, which declares its plug-in (``report.loggers.base``: what it receives and declares),
and one line in ``LOGGERS``; ``LogSettings``, config.json's ``log`` section, joins each logger's settings to
the choice of loggers (``plugins.joined``), so their flags, TOML keys, config.json keys, checks and docs come
from their declarations.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from plugins import Registry, joined
from report.loggers import mlflow, tensorboard, wandb
from report.loggers.base import GROUP, LoggerPlugin, scalars
from settings import check, setting

LOGGERS: Registry[LoggerPlugin] = Registry("logger", [
    tensorboard.PLUGIN,
    wandb.PLUGIN,
    mlflow.PLUGIN,
])


@dataclass(frozen=True)
class LoggerChoice:
    """Where the run is logged beside its files; none of it changes a result. Then (``LogSettings``) each
    logger's own settings, in the registry's order."""

    logger: tuple[str, ...] = setting((), choices=LOGGERS, aliases={"tensorboard": "tensorboard"}, resumable=True,
                                      metavar="NAME", group=GROUP, shown_default="none",
                                      help="also send the run to these experiment trackers: its settings once, every "
                                           "metrics.csv row at its generation, its figures and final weights at the "
                                           "end (docs/modern-es.md)")

    def __post_init__(self) -> None:
        check(self)
        object.__setattr__(self, "logger", tuple(dict.fromkeys(self.logger)))  # each once, in the order given


LogSettings = joined(LoggerChoice, LOGGERS, name="LogSettings", module=__name__)


def missing(settings) -> str | None:
    """One line for the first logger whose packages are not installed, with its install command."""
    for name in settings.logger:
        absent = LOGGERS[name].missing()
        if absent:
            return (f"--logger {name} needs the {', '.join(absent)} package{'s' if len(absent) > 1 else ''}, which "
                    f"{'are' if len(absent) > 1 else 'is'} not installed; install {'them' if len(absent) > 1 else 'it'}"
                    f" with: {LOGGERS[name].install_hint}")
    return None


class Loggers:
    """The loggers ``settings`` name, made for the run folder ``run_folder``, in the order the training script
    calls them. A logger that fails as the run starts stops it (one line); one that fails later is dropped with a
    warning, and the run goes on."""

    def __init__(self, settings, run_folder: Path, extra_columns: tuple[str, ...] = (),
                 say: Callable[[str], None] = print):
        self.loggers = {name: LOGGERS[name].make(settings, Path(run_folder), say) for name in settings.logger}
        self.extra_columns, self.say, self.done = extra_columns, say, False

    def begin(self, record: dict, generation: int) -> dict:
        """The run's settings as config.json records them, as it starts (generation 0) or resumes after
        ``generation``; what config.json should record of the loggers (their trackers' run ids)."""
        recorded = {}
        for name, logger in self.loggers.items():
            try:
                recorded.update(logger.begin(record, generation))
            except Exception as error:  # a tracker's own exceptions: the store unreachable, a bad URI
                first = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
                raise ValueError(f"--logger {name}: {first}") from None
        return recorded

    def generation(self, row: dict) -> None:
        """A generation's metrics row."""
        step, values = int(row["generation"]), scalars(row, self.extra_columns)
        self._each(lambda logger: logger.log(step, values))

    def saved(self) -> None:
        """After a save of the run's files."""
        self._each(lambda logger: logger.flush())

    def finished(self, run_folder: Path) -> None:
        """The run has run all its generations: its figures and final weight files."""
        figures = sorted(Path(run_folder).glob("*.png"))
        weights = sorted(path for prefix in ("last", "best") for path in Path(run_folder).glob(f"{prefix}*"))
        self._each(lambda logger: logger.artefacts(figures, weights))
        self.done = True

    def close(self) -> None:
        self._each(lambda logger: logger.close(self.done))

    def _each(self, call: Callable) -> None:
        for name, logger in list(self.loggers.items()):
            try:
                call(logger)
            except Exception as error:  # a tracker lost (network, disk): the run is worth more than its log
                self.say(f"warning: --logger {name} failed ({type(error).__name__}: {error}); the run goes on "
                         "without it")
                del self.loggers[name]


__all__ = ["LOGGERS", "LogSettings", "Loggers", "missing"]
