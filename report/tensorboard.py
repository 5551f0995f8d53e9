"""``--tensorboard``: every metrics column as a TensorBoard scalar, under ``<run folder>/tensorboard``.

A reporter of the generation loop (``es.loop.Reporter``), like ``report.log``'s: it receives each
generation's metrics row and writes one scalar per numeric column (``metrics.csv``'s columns, the
generation as the step); values a generation does not have (NaN, empty) are left out. The writer is
PyTorch's ``SummaryWriter``, which needs the optional ``tensorboard`` package
(``requirements-tensorboard.txt``). After a resume, the generations between the checkpoint and the
stop are run again: the writer starts with TensorBoard's purge marker at the first generation it
writes (``SummaryWriter(purge_step=...)``), so TensorBoard drops the earlier events from that step
on and each generation appears once.
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

from es.files import METRICS_COLUMNS

FOLDER = "tensorboard"
INSTALL_HINT = "pip install -r requirements-tensorboard.txt (or pip install -e .[tensorboard])"


def available() -> bool:
    return importlib.util.find_spec("tensorboard") is not None


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


class TensorBoardLog:
    """Writes each generation's metrics row as scalars; flushes at every save. The writer (and its
    folder) is made at the first generation, so a run that fails to start leaves nothing behind."""

    def __init__(self, run_folder: Path, extra_columns: tuple[str, ...] = ()):
        self.path = Path(run_folder) / FOLDER
        self.extra_columns = extra_columns  # the policy kind's metrics columns (``Policy.metrics_columns``)
        self.writer = None

    def generation(self, row: dict) -> None:
        step = int(row["generation"])
        if self.writer is None:  # the first generation this process writes; a resumed run's later events go
            from torch.utils.tensorboard import SummaryWriter

            self.writer = SummaryWriter(log_dir=str(self.path), purge_step=step)
        for name, value in scalars(row, self.extra_columns).items():
            self.writer.add_scalar(name, value, step)

    def saved(self, folder, rows: list[dict]) -> None:
        if self.writer is not None:
            self.writer.flush()

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
