"""What a training run shows and sends as it goes, owned by the training script (``cli.train``): its line per
generation, its ``fitness.png`` (``report.log``) and the experiment trackers of ``--logger`` (``report.loggers``).

The script makes them before anything else of the run, passes ``RunReport`` to the loop as its one callback,
which hands it each generation's record (``es.loop.GenerationRecord``), tells them the run's folder and settings
as it writes config.json (``begin``) and that the run has finished (``finished``), and closes them as the
process ends. The loop knows none of them.
"""

from __future__ import annotations

from collections.abc import Callable

from cli.errors import UserError
from es.loop import GenerationRecord
from es.runfolder import RunFolder
from report.log import FitnessPlot, GenerationLog
from report.loggers import Loggers, missing


def check_loggers(log_settings) -> None:
    """Refuse, before anything starts, a --logger whose packages are not installed."""
    if (problem := missing(log_settings)) is not None:
        raise UserError(problem)


class RunReport:
    """Made before anything else of the run (it refuses a --logger whose packages are missing); ``begin`` makes
    the loggers in the run's folder and starts them."""

    def __init__(self, log_settings, say: Callable[[str], None]):
        check_loggers(log_settings)
        self.settings, self.say = log_settings, say
        self.lines = GenerationLog(say)
        self.plot = FitnessPlot()
        self.folder: RunFolder | None = None
        self.loggers: Loggers | None = None

    def begin(self, folder: RunFolder, record: dict, generation: int, extra_columns: tuple[str, ...] = ()) -> dict:
        """The run's folder, and the settings config.json records, as the run starts (generation 0) or resumes
        after ``generation``; ``extra_columns``: the policy's metrics columns. What config.json should record of
        the loggers (their trackers' run ids)."""
        self.folder = folder
        self.loggers = Loggers(self.settings, folder.path, extra_columns, self.say)
        return self.loggers.begin(record, generation)

    def __call__(self, record: GenerationRecord) -> None:
        """A generation's record, as the loop hands it on."""
        self.lines.generation(record.row)
        self.loggers.generation(record.row)
        if record.saved:
            self.plot.saved(self.folder, record.rows)
            self.loggers.saved()

    def finished(self) -> None:
        """The run has run all its generations: the figure drawn, then sent with the final weights."""
        self.plot.finished(self.folder)
        self.loggers.finished(self.folder.path)

    def close(self) -> None:
        self.plot.close()
        if self.loggers is not None:
            self.loggers.close()
