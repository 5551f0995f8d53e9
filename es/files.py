"""Files of a run: atomic writes, the original ``.dat`` format and names, safe loading.

A ``.dat`` file is what the original wrote: a float32 numpy array saved with ``torch.save``.
Loading uses ``torch.load(weights_only=True)`` with only the numpy names such an array needs
allow-listed (under both their numpy 1 and numpy 2 module paths, since the original files were
written with numpy 1), so a file that would run code when unpickled is refused.
"""

from __future__ import annotations

import csv
import errno
import io
import json
import os
import re
import shutil
import tempfile
import zipfile
from pathlib import Path

import numpy as np


class FileFormatError(ValueError):
    """A weight file that is missing, corrupt or not a plain array."""


def _umask() -> int:
    current = os.umask(0)
    os.umask(current)
    return current


_FILE_MODE = 0o666 & ~_umask()  # what open() would give; mkstemp's files are private (0600)


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write to a temporary file in the same folder, fsync, then rename over ``path``.

    A crash at any moment leaves either the old file or the new one, never a torn one.
    """
    path = Path(path)
    if path.exists() and not path.is_file():  # never rename over a folder, a device or a pipe
        raise OSError(f"{path} exists and is not a regular file")
    descriptor, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(descriptor, _FILE_MODE)
        with os.fdopen(descriptor, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(temporary, path)
    except BaseException:
        try:
            os.unlink(temporary)
        except FileNotFoundError:
            pass
        raise


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write_bytes(path, text.encode())


def save_dat(path: Path, array: np.ndarray) -> None:
    """``torch.save`` of a float32 array, atomically, named inside as ``torch.save(path)`` names it.

    torch's zip archive has one top-level folder, the file's stem (``<stem>/data.pkl``), where
    saving to a buffer would name it ``archive/``; readers of the original files open
    ``<stem>/data.pkl``. So the file is written under its own name in a temporary folder beside
    the target, synced, then renamed over it.
    """
    import torch

    path = Path(path)
    if path.exists() and not path.is_file():  # never rename over a folder, a device or a pipe
        raise OSError(f"{path} exists and is not a regular file")
    staging = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp"))
    try:
        staged = staging / path.name
        array = np.asarray(array, dtype=np.float32)
        try:
            torch.save(array, staged)
        except RuntimeError as error:  # torch's writer reports a failed write without its errno
            raise write_failure(staging, array.nbytes, error) from None
        os.chmod(staged, _FILE_MODE)
        with open(staged, "rb") as handle:
            os.fsync(handle.fileno())
        os.replace(staged, path)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def write_failure(folder: Path, size: int, error: Exception) -> OSError:
    """The OSError behind a library's failed write of ``size`` bytes into ``folder``: a full disk, known by
    the space left, or the library's own words."""
    stats = os.statvfs(folder)
    if stats.f_bavail * stats.f_frsize < size:
        return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    words = str(error).strip().splitlines()
    return OSError(errno.EIO, f"{type(error).__name__}: {words[0] if words else 'the write failed'}")


def _numpy_safe_globals() -> list:
    # The function numpy's pickles of arrays call, taken from the public pickle protocol rather than
    # from numpy's private module (numpy 2 names it numpy._core.multiarray._reconstruct).
    reconstruct = np.ndarray(0).__reduce__()[0]
    return [np.ndarray, np.dtype, reconstruct, (reconstruct, "numpy.core.multiarray._reconstruct"),
            *(type(np.dtype(code)) for code in "fdeihlqbBHIL?")]


def _refusal_reason(error: Exception) -> str:
    """The informative part of torch's weights_only refusal.

    torch's first lines are boilerplate advising ``weights_only=False``, exactly what must not be
    done with an untrusted file; the global it refused (``GLOBAL posix.system``) or the unpickler's
    own complaint comes later.
    """
    text = str(error)
    match = re.search(r"GLOBAL ([\w.]+)", text)
    if match:
        return f"it asks to import {match.group(1)}, which could run code"
    complaint = re.search(r"WeightsUnpickler error:\s*(\S.*)", text)
    if complaint:
        return complaint.group(1).strip()
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    return lines[0] if lines else type(error).__name__


def _check_weight_file(path: Path) -> None:
    """Refuse what cannot be a weight file, naming why, before torch is imported."""
    name = repr(str(path))
    if not path.exists():
        raise FileFormatError(f"weight file {name} does not exist")
    if path.is_dir():
        raise FileFormatError(f"weight file {name} is a folder; give the .dat file in it")
    if not path.is_file():
        raise FileFormatError(f"weight file {name} is not a regular file (a device or a pipe); give a .dat file")
    with open(path, "rb") as handle:
        head = handle.read(2)
    if not head:
        raise FileFormatError(f"weight file {name} is empty")
    if head == b"PK":  # torch's zip format: the central directory is at the end, so a cut file loses it
        if not zipfile.is_zipfile(path):
            raise FileFormatError(f"weight file {name} is truncated or corrupt (an incomplete zip archive)")
    elif head[:1] != b"\x80":  # nor torch's legacy format, a pickle
        raise FileFormatError(f"{name} is not a weight file: it was not written by torch.save (it starts with "
                              f"{head!r}; a .dat file is a numpy array saved with torch.save)")


def load_dat(path: str | Path) -> np.ndarray:
    """A ``.dat`` weight file as a finite float32 array (tensors are accepted too, bfloat16 included)."""
    import pickle

    path = Path(path)
    _check_weight_file(path)
    import torch

    try:
        with torch.serialization.safe_globals(_numpy_safe_globals()):
            loaded = torch.load(path, weights_only=True, map_location="cpu")
    except pickle.UnpicklingError as error:
        reason = _refusal_reason(error)
        raise FileFormatError(f"refused to load {str(path)!r}: not a plain weight array ({reason}); "
                              "only numpy arrays or tensors saved with torch.save are accepted") from None
    except Exception as error:
        detail = str(error).split(". ")[0].splitlines()[0] if str(error) else ""
        raise FileFormatError(f"weight file {str(path)!r} is truncated or corrupt ({type(error).__name__}: "
                              f"{detail})") from None
    if isinstance(loaded, torch.Tensor):
        tensor = loaded.detach().cpu()
        loaded = (tensor.float() if tensor.is_floating_point() else tensor).numpy()  # numpy has no bfloat16
    if not isinstance(loaded, np.ndarray) or not np.issubdtype(loaded.dtype, np.number):
        raise FileFormatError(f"{str(path)!r} holds a {type(loaded).__name__}, not a numeric array")
    array = loaded.astype(np.float32)
    bad = int(np.size(array) - np.count_nonzero(np.isfinite(array)))
    if bad:
        raise FileFormatError(f"{str(path)!r} holds {bad} NaN or infinite values; a weight file must hold finite "
                              "numbers")
    return array


def save_npy(path: Path, array: np.ndarray) -> None:
    buffer = io.BytesIO()
    np.save(buffer, array)
    atomic_write_bytes(path, buffer.getvalue())


# --- config and metrics -------------------------------------------------------------------------


def write_json(path: Path, data: dict) -> None:
    atomic_write_text(path, json.dumps(data, indent=2, sort_keys=False) + "\n")


def read_json(path: Path) -> dict:
    return json.loads(_read_regular(path))


METRICS_COLUMNS = ("generation", "fitness_mean", "fitness_max", "fitness_min", "fitness_std",
                   "return_mean", "center_return", "sigma", "lr", "update_factor", "skipped",
                   "nonfinite", "env_steps", "total_env_steps", "seconds", "total_seconds",
                   "center_rank", "center_eval_mean", "center_eval_std", "episode_cap")
LATER_COLUMNS = ("center_rank", "center_eval_mean", "center_eval_std", "episode_cap")  # absent from earlier files


def write_metrics(path: Path, rows: list[dict], extra_columns: tuple[str, ...] = ()) -> None:
    """Rewrite metrics.csv whole (atomically): it is small, and a resume must drop later rows.
    Rows read back from a metrics.csv of an earlier version lack the later columns: left empty.
    ``extra_columns`` are the policy kind's own (``Policy.metrics_columns``), after the common ones."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=METRICS_COLUMNS + tuple(extra_columns))
    writer.writeheader()
    for row in rows:
        writer.writerow({key: row.get(key, "") if key in LATER_COLUMNS else row[key] for key in METRICS_COLUMNS}
                        | {key: row.get(key, "") for key in extra_columns})
    atomic_write_text(path, buffer.getvalue())


def read_metrics(path: Path) -> list[dict]:
    return list(csv.DictReader(io.StringIO(_read_regular(path), newline="")))


def read_whole_metrics(path: Path) -> tuple[list[dict], int | None]:
    """The rows of metrics.csv before the first damaged one, and that row's line (None if there is none).
    A row is damaged when it lacks fields or has fields too many, or is the last and has no line end: a
    file cut mid-row (every write is atomic, so only damage from outside cuts one)."""
    text = _read_regular(path)
    reader = csv.DictReader(io.StringIO(text, newline=""))
    rows = []
    for row in reader:
        if None in row or None in row.values():
            return rows, reader.line_num
        rows.append(row)
    if text and not text.endswith("\n"):
        return rows[:-1], reader.line_num
    return rows, None


def _read_regular(path: Path) -> str:
    """A text file's content; a folder, a device or a named pipe (which would block a read) is refused."""
    path = Path(path)
    if path.exists() and not path.is_file():
        raise FileFormatError(f"{path} is not a regular file (a folder, a device or a pipe)")
    with open(path, newline="") as handle:
        return handle.read()
