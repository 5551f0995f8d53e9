"""The guard every output path passes before anything is computed: an output never replaces a run's file.

A user names outputs (``--json``, ``--plot``, ``--video``, ``plot_run.py -o``, the comparison's
results); a typo or a tab completion can point one at a file a run needs. ``check_output`` refuses,
in one line, a path that

- resolves (links followed) to a file of a run folder: a folder holding ``config.json`` or
  ``checkpoint.npz`` (``es.runfolder``), whose own files are named as in ``RUN_FILES`` (config,
  checkpoint, weights ``.dat``, ``.npz`` statistics, metrics, the fitness log and picture, logs,
  journals, the lock) or lie in one of its sub-folders (TensorBoard's events), or that exists there
  already (an ``evaluation.json``, ``adaptation.png`` or ``frames.png`` an evaluation wrote); new names
  there, such as a first ``evaluation.json``, are allowed;
- is anywhere an optuna journal of ER-MRL (``optuna-journal_*.log``) or a file the same command reads;
- has a suffix that is not one of the formats the output is written in (a PNG is never written
  under ``.jpg``), or is a folder or a device, or lies in a folder that does not exist or where no
  file can be created (tried: permissions alone do not say so for root, nor for a read-only mount).

The writers then write to a temporary file and rename it over the target (``es.files``).
"""

from __future__ import annotations

import fnmatch
import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

from es.runfolder import RunFolderError

RUN_MARKERS = ("config.json", "checkpoint.npz")
RUN_FILES = ("config.json", "checkpoint.npz", "metrics.csv", "fitness.png", "*.dat", "*.npz", "*.npy", "*.csv",
             "*.log", ".lock", ".*.tmp", "optuna-journal_*")
JOURNAL = "optuna-journal_*.log"
JSON_SUFFIXES = (".json",)


class OutputRefused(RunFolderError):
    """An output path that would replace a run's file or an input, or is not of a format it can be written in."""


def run_folder_of(path: Path) -> Path | None:
    """The run folder ``path`` lies in (directly or in a sub-folder of it), or None."""
    for folder in list(path.parents)[:3]:
        if any((folder / marker).is_file() for marker in RUN_MARKERS):
            return folder
    return None


def same_file(first: str | Path, second: str | Path) -> bool:
    """The same file once links are resolved (or the same path, for files not there yet)."""
    first, second = Path(first), Path(second)
    try:
        if first.exists() and second.exists():
            return os.path.samefile(first, second)
    except OSError:
        pass
    return first.resolve() == second.resolve()


def can_create_in(folder: Path) -> bool:
    """Whether a file can be created in ``folder``: one is, as the writers' temporary files are, and removed."""
    try:
        descriptor, name = tempfile.mkstemp(dir=folder, prefix=".", suffix=".tmp")
    except OSError:
        return False
    os.close(descriptor)
    os.unlink(name)
    return True


def check_output(flag: str, path: str | Path, suffixes: tuple[str, ...], inputs: Iterable[str | Path] = ()) -> Path:
    """``path`` as the output ``flag`` names, or an OutputRefused naming why it cannot be one."""
    given = str(path)
    target = Path(path)
    if target.exists() and not target.is_file():
        raise OutputRefused(f"{flag} {given}: exists and is not a regular file (a folder or a device); give a file "
                            "name")
    resolved = target.resolve()
    if not resolved.parent.is_dir() or not can_create_in(resolved.parent):
        raise OutputRefused(f"{flag} {given}: {target.parent} is not an existing writable folder")
    for other in inputs:
        if same_file(target, other):
            raise OutputRefused(f"{flag} {given} is {other}, which this command reads (a weight file or one beside "
                                "it); writing it would destroy the input: give another file name")
    run = run_folder_of(resolved)
    if run is not None and (resolved.parent != run
                            or any(fnmatch.fnmatch(resolved.name, pattern) for pattern in RUN_FILES)):
        raise OutputRefused(f"{flag} {given} is {resolved.relative_to(run)} of the run folder {run}, a file the run "
                            "writes; give another file name")
    if run is not None and resolved.exists():
        raise OutputRefused(f"{flag} {given} is {resolved.name} of the run folder {run}, which exists: an output never "
                            "replaces a run's file; give another file name")
    if fnmatch.fnmatch(resolved.name, JOURNAL):
        raise OutputRefused(f"{flag} {given} is an optuna journal of ER-MRL; give another file name")
    if target.suffix.lower() not in suffixes:
        raise OutputRefused(f"{flag} {given}: the file's suffix says its format; give a name ending in "
                            f"{', '.join(suffixes)}")
    return target


def check_outputs(outputs: list[tuple[str, str | Path, tuple[str, ...]]], inputs: Iterable[str | Path] = ()) -> None:
    """Each output (flag, path, suffixes) checked, and no two the same file."""
    for index, (flag, path, _) in enumerate(outputs):
        for other_flag, other, _ in outputs[index + 1:]:
            if same_file(path, other):
                raise OutputRefused(f"{flag} and {other_flag} are the same file {path}; give each its own name")
    inputs = list(inputs)
    for flag, path, suffixes in outputs:
        check_output(flag, path, suffixes, inputs)
