"""``--logger tensorboard`` (``--tensorboard``): every metrics column as a TensorBoard scalar, under
``<run folder>/tensorboard``, the generation as the step.

The writer is PyTorch's ``SummaryWriter``, which needs the optional ``tensorboard`` package
(``requirements-tensorboard.txt``). It is made at the first row this process writes, so a run that fails
to start leaves nothing behind. After a resume, the generations between the checkpoint and the stop are
run again: the writer starts with TensorBoard's purge marker at the first generation it writes
(``SummaryWriter(purge_step=...)``), so TensorBoard drops the earlier events from that step on and each
generation appears once. The figures and weight files are the run folder's already: it sends no
artefacts.
"""

from __future__ import annotations

from pathlib import Path

from report.loggers.base import LoggerPlugin

FOLDER = "tensorboard"


class TensorBoardLogger:
    def __init__(self, settings, run_folder: Path, say=print):
        self.path = Path(run_folder) / FOLDER
        self.writer = None

    def begin(self, record: dict, generation: int) -> dict:
        return {}

    def log(self, step: int, values: dict[str, float]) -> None:
        if self.writer is None:  # the first generation this process writes; a resumed run's later events go
            from torch.utils.tensorboard import SummaryWriter

            self.writer = SummaryWriter(log_dir=str(self.path), purge_step=step)
        for name, value in values.items():
            self.writer.add_scalar(name, value, step)

    def flush(self) -> None:
        if self.writer is not None:
            self.writer.flush()

    def artefacts(self, figures: list[Path], weights: list[Path]) -> None:
        pass

    def close(self, finished: bool) -> None:
        if self.writer is not None:
            self.writer.close()


PLUGIN = LoggerPlugin("tensorboard", about="TensorBoard scalars in <run>/tensorboard", make=TensorBoardLogger,
                      modules=("tensorboard",), extra="tensorboard")
