"""Files of a run: atomic writes, the original ``.dat`` format and names, safe loading.

A ``.dat`` file is what the original wrote: a float32 numpy array saved with ``torch.save``, which is
a zip archive holding ``<stem>/data.pkl`` (the array pickled with protocol 2) and a few small
records. This module writes that archive itself, the same ``data.pkl`` byte for byte, so that no run
imports torch (about 2 s and 200 MB) to save its weights; torch and the original code load it.

Loading unpickles ``data.pkl`` with only the names a numpy array needs allow-listed (under both their
numpy 1 and numpy 2 module paths, since the original files were written with numpy 1), so a file
that would run code when unpickled is refused. A file holding a torch tensor, or in torch's legacy
(pre-zip) format, goes to ``torch.load(weights_only=True)`` with the same allow-list.
"""

from __future__ import annotations

import codecs
import csv
import io
import json
import os
import pickle
import re
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


_DAT_RECORDS = ((".format_version", b"1"), (".storage_alignment", b"64"), ("byteorder", b"little"),
                ("version", b"3\n"))  # what torch.save writes beside data.pkl (torch 2.13)
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)  # fixed: the same array gives the same file


def dat_bytes(name: str, array: np.ndarray) -> bytes:
    """The bytes of ``torch.save(array)`` to a file named ``name``, for a float32 array: a stored (not
    compressed) zip archive whose one folder is the name's stem, as torch names it."""
    folder = Path(name).stem
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_STORED) as archive:
        entries = (("data.pkl", pickle.dumps(np.asarray(array, dtype=np.float32), protocol=2)), *_DAT_RECORDS)
        for entry, data in entries:
            archive.writestr(zipfile.ZipInfo(f"{folder}/{entry}", _ZIP_TIME), data)
    return buffer.getvalue()


def save_dat(path: Path, array: np.ndarray) -> None:
    """A float32 array as the original's ``.dat`` file (``dat_bytes``), atomically."""
    path = Path(path)
    atomic_write_bytes(path, dat_bytes(path.name, array))


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


class _NeedsTorch(Exception):
    """The pickle holds a torch tensor: torch's own loader reads it."""


def _allowed_globals() -> dict[tuple[str, str], object]:
    """(module, name) -> object: what a pickled numpy array may ask for (``_numpy_safe_globals``), and
    ``_codecs.encode``, with which protocol 2 pickles the array's bytes."""
    allowed = {("_codecs", "encode"): codecs.encode}
    for item in _numpy_safe_globals():
        target, name = item if isinstance(item, tuple) else (item, f"{item.__module__}.{item.__qualname__}")
        module, _, attribute = name.rpartition(".")
        allowed[(module, attribute)] = target
    return allowed


class _ArrayUnpickler(pickle.Unpickler):
    """Unpickles what a .dat file may hold: numpy arrays and plain data; anything else is refused, named."""

    allowed = _allowed_globals()

    def find_class(self, module: str, name: str):
        if (module, name) in self.allowed:
            return self.allowed[(module, name)]
        if module == "torch" or module.startswith("torch."):
            raise _NeedsTorch
        raise pickle.UnpicklingError(f"GLOBAL {module}.{name}")  # _refusal_reason names it

    def persistent_load(self, pid):  # a tensor's storage
        raise _NeedsTorch


def _unpickled_archive(path: Path):
    """The object of a zip-format .dat file, unpickled without torch; _NeedsTorch for a tensor."""
    with zipfile.ZipFile(path) as archive:
        pickles = [name for name in archive.namelist() if name.endswith("/data.pkl") and name.count("/") == 1]
        if len(pickles) != 1:
            raise ValueError(f"{len(pickles)} data.pkl records in the archive, not one")
        data = archive.read(pickles[0])
    return _ArrayUnpickler(io.BytesIO(data)).load()


def _torch_load(path: Path):
    import torch

    with torch.serialization.safe_globals(_numpy_safe_globals()):
        loaded = torch.load(path, weights_only=True, map_location="cpu")
    if isinstance(loaded, torch.Tensor):
        tensor = loaded.detach().cpu()
        loaded = (tensor.float() if tensor.is_floating_point() else tensor).numpy()  # numpy has no bfloat16
    return loaded


def load_dat(path: str | Path) -> np.ndarray:
    """A ``.dat`` weight file as a finite float32 array (tensors are accepted too, bfloat16 included)."""
    path = Path(path)
    _check_weight_file(path)
    try:
        try:
            loaded = _unpickled_archive(path) if zipfile.is_zipfile(path) else _torch_load(path)
        except _NeedsTorch:
            loaded = _torch_load(path)
    except pickle.UnpicklingError as error:
        reason = _refusal_reason(error)
        raise FileFormatError(f"refused to load {str(path)!r}: not a plain weight array ({reason}); "
                              "only numpy arrays or tensors saved with torch.save are accepted") from None
    except Exception as error:
        detail = str(error).split(". ")[0].splitlines()[0] if str(error) else ""
        raise FileFormatError(f"weight file {str(path)!r} is truncated or corrupt ({type(error).__name__}: "
                              f"{detail})") from None
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
