"""Files of a run: atomic writes, the original ``.dat`` format and names, safe loading.

A ``.dat`` file is what the original wrote: a float32 numpy array saved with ``torch.save``.
Loading uses ``torch.load(weights_only=True)`` with only the numpy names such an array needs
allow-listed (under both their numpy 1 and numpy 2 module paths, since the original files were
written with numpy 1), so a file that would run code when unpickled is refused.
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
import tempfile
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
    import torch

    buffer = io.BytesIO()
    torch.save(np.asarray(array, dtype=np.float32), buffer)
    atomic_write_bytes(path, buffer.getvalue())


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


def load_dat(path: str | Path) -> np.ndarray:
    """A ``.dat`` weight file as a float32 array (tensors are accepted too)."""
    import pickle

    path = Path(path)
    if not path.is_file():  # before importing torch: a typo should fail at once
        raise FileFormatError(f"weight file {str(path)!r} does not exist")
    import torch

    try:
        with torch.serialization.safe_globals(_numpy_safe_globals()):
            loaded = torch.load(path, weights_only=True, map_location="cpu")
    except pickle.UnpicklingError as error:
        reason = _refusal_reason(error)
        raise FileFormatError(f"refused to load {str(path)!r}: not a plain weight array ({reason}); "
                              "only numpy arrays or tensors saved with torch.save are accepted") from None
    except Exception as error:
        raise FileFormatError(f"cannot read weight file {str(path)!r}: {type(error).__name__}: "
                              f"{str(error).splitlines()[0] if str(error) else ''}") from None
    if isinstance(loaded, torch.Tensor):
        loaded = loaded.detach().cpu().numpy()
    if not isinstance(loaded, np.ndarray) or not np.issubdtype(loaded.dtype, np.number):
        raise FileFormatError(f"{str(path)!r} holds a {type(loaded).__name__}, not a numeric array")
    return loaded.astype(np.float32)


def save_npy(path: Path, array: np.ndarray) -> None:
    buffer = io.BytesIO()
    np.save(buffer, array)
    atomic_write_bytes(path, buffer.getvalue())


# --- config and metrics -------------------------------------------------------------------------


def write_json(path: Path, data: dict) -> None:
    atomic_write_text(path, json.dumps(data, indent=2, sort_keys=False) + "\n")


def read_json(path: Path) -> dict:
    with open(path) as handle:
        return json.load(handle)


METRICS_COLUMNS = ("generation", "fitness_mean", "fitness_max", "fitness_min", "fitness_std",
                   "return_mean", "center_return", "sigma", "lr", "update_factor", "skipped",
                   "nonfinite", "env_steps", "total_env_steps", "seconds", "total_seconds",
                   "center_rank", "center_eval_mean", "center_eval_std")
LATER_COLUMNS = ("center_rank", "center_eval_mean", "center_eval_std")  # absent from earlier versions' files


def write_metrics(path: Path, rows: list[dict]) -> None:
    """Rewrite metrics.csv whole (atomically): it is small, and a resume must drop later rows.
    Rows read back from a metrics.csv of an earlier version lack the later columns: left empty."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=METRICS_COLUMNS)
    writer.writeheader()
    for row in rows:
        writer.writerow({key: row.get(key, "") if key in LATER_COLUMNS else row[key] for key in METRICS_COLUMNS})
    atomic_write_text(path, buffer.getvalue())


def read_metrics(path: Path) -> list[dict]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))
