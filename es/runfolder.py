"""The files of a run: where they live, their names, and the checkpoint.

``<folder>/<time>_<env>_seed<seed>/`` holds the original project's files (``.dat`` parameter files
named as upstream by the policy, ``Fitness_values_<run>_<env>.npy``), ``best``/``last`` copies of
the parameters, ``config.json``, ``metrics.csv`` and ``checkpoint.npz``; with ``--obs_norm``, a
``<name>.obs_norm.npz`` of observation statistics beside each weight file (``es.observations``).
Every write is atomic (``es.files``), and an OSError becomes a ``SaveError`` that names the file.
The checkpoint is the fields of one dataclass, ``Checkpoint``, written and read by iterating over
them; a field holding a dict of arrays (the optimiser's, the strategy's, the observation statistics) is
stored as one array per key, ``<field>.<key>``, and is empty in checkpoints written before it existed.

A resume trusts nothing in the folder: ``check_resumable`` reads the checkpoint and metrics and refuses,
before anything runs or is written, one whose generation, sizes or optimiser state do not match each
other or the run's settings, or that holds NaN or infinity. A process that uses a folder holds an
exclusive ``flock`` on its ``.lock`` file until it exits, so a second process cannot resume it meanwhile.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import io
import json
import math
import os
import shutil
import stat
import time
import typing
from collections.abc import Callable
from dataclasses import MISSING, dataclass, field, fields, replace
from pathlib import Path

import numpy as np

from es import files
from es.observations import RunningStat, statistics_bytes, statistics_path
from es.optimizers import make_optimizer
from es.settings import ESSettings
from es.strategy import ESState

LOCK_FILE = ".lock"


class SaveError(RuntimeError):
    """A file of the run could not be written (disk full, folder made read-only); names the file."""


class RunFolderError(ValueError):
    """A run folder that cannot be used: not a run, an unreadable checkpoint or metrics file."""


@dataclass
class History:
    """What a run has done so far, beyond the strategy state: saved in the checkpoint."""

    best_theta: np.ndarray | None = None  # the centre with the best return (or evaluation mean) so far
    best_center: float = -math.inf
    best_observations: RunningStat | None = None  # --obs_norm: the statistics best_theta was evaluated with
    fitness_log: list[float] = field(default_factory=list)  # the original's Fitness_values file
    metrics: list[dict] = field(default_factory=list)
    total_steps: int = 0
    total_seconds: float = 0.0
    episode_cap: int = 0  # --variable_ep_len: the next generation's cap on env steps (0: none yet)


@dataclass
class Checkpoint:
    """Everything a resume needs beyond config.json; one array per field in checkpoint.npz."""

    theta: np.ndarray
    lr: float
    sigma: float
    generation: int
    best_theta: np.ndarray  # empty until a centre has scored
    best_center: float
    fitness_log: np.ndarray  # the original's Fitness_values file
    total_steps: int
    total_seconds: float
    optimizer: dict[str, np.ndarray] = field(default_factory=dict)  # e.g. Adam's m, v and t
    observations: dict[str, np.ndarray] = field(default_factory=dict)  # --obs_norm: RunningStat's sums
    best_observations: dict[str, np.ndarray] = field(default_factory=dict)  # those best_theta was evaluated with
    episode_cap: int = 0  # --variable_ep_len: the next generation's cap (0: none)
    strategy: dict[str, np.ndarray] = field(default_factory=dict)  # the strategy's arrays (es.strategies)
    # the settings it was written under but those a resume may change (``settings_record``), and their
    # digest; empty in checkpoints written before they were recorded
    settings: str = ""
    settings_digest: str = ""

    @classmethod
    def of(cls, state: ESState, history: History, observations: RunningStat | None = None) -> Checkpoint:
        best = history.best_theta if history.best_theta is not None else np.zeros(0, np.float32)
        return cls(theta=state.theta, lr=state.lr, sigma=state.sigma, generation=state.generation,
                   best_theta=best, best_center=history.best_center, fitness_log=np.array(history.fitness_log),
                   total_steps=history.total_steps, total_seconds=history.total_seconds, optimizer=state.optimizer,
                   observations=observations.to_arrays() if observations is not None else {},
                   best_observations=(history.best_observations.to_arrays()
                                      if history.best_observations is not None else {}),
                   episode_cap=history.episode_cap, strategy=state.strategy)

    def state(self) -> ESState:
        return ESState(self.theta.astype(np.float32), self.lr, self.sigma, self.generation, dict(self.optimizer),
                       dict(self.strategy))

    def history(self, metrics: list[dict]) -> History:
        return History(best_theta=self.best_theta if self.best_theta.size else None, best_center=self.best_center,
                       best_observations=RunningStat.from_arrays(self.best_observations),
                       fitness_log=[float(value) for value in self.fitness_log], metrics=metrics,
                       total_steps=self.total_steps, total_seconds=self.total_seconds, episode_cap=self.episode_cap)

    def to_bytes(self) -> bytes:
        arrays = {}
        for item in fields(self):
            value = getattr(self, item.name)
            if isinstance(value, dict):
                arrays.update({f"{item.name}.{key}": np.asarray(array) for key, array in value.items()})
            else:
                arrays[item.name] = np.asarray(value)
        buffer = io.BytesIO()
        np.savez(buffer, **arrays)
        return buffer.getvalue()

    @classmethod
    def from_file(cls, path: Path) -> Checkpoint:
        types = typing.get_type_hints(cls)
        with np.load(path) as saved:  # a field added later is absent from older checkpoints: its default
            return cls(**{item.name: _decode(saved, item.name, types[item.name]) for item in fields(cls)
                          if item.name in saved.files or item.default is MISSING})


def _decode(saved, name: str, kind: type):
    if typing.get_origin(kind) is dict:
        prefix = f"{name}."
        return {key[len(prefix):]: np.array(saved[key]) for key in saved.files if key.startswith(prefix)}
    if kind is np.ndarray:
        return np.array(saved[name])
    return kind(saved[name])


def settings_record(values: dict) -> str:
    """The text a checkpoint records of the settings it was written under: JSON, keys sorted."""
    return json.dumps(values, sort_keys=True, separators=(",", ":"))


def settings_digest(record: str) -> str:
    return hashlib.sha256(record.encode()).hexdigest()


def named_file(prefix: str, role: str) -> str:
    """``best.dat`` / ``last.dat`` for static weights, ``<prefix>_<role>.dat`` for Hebbian parts."""
    return f"{prefix}.dat" if role == "weights" else f"{prefix}_{role}.dat"


def fitness_file_name(run_id: str, env: str) -> str:
    return f"Fitness_values_{run_id}_{env}.npy"


@dataclass
class RunFolder:
    path: Path
    checkpoint_generation: int | None = field(default=None)  # the generation checkpoint.npz holds
    made_parents: list[Path] = field(default_factory=list)  # the folders above it that creating it made
    settings: str = ""  # the settings_record its checkpoints are written under (set with config.json)

    @classmethod
    def create(cls, folder: str | Path, label: str, seed: int) -> RunFolder:
        """A fresh run folder ``<folder>/<time>_<env>_seed<seed>``; never an existing one."""
        folder = Path(folder)
        made = [parent for parent in (folder, *folder.parents) if not parent.exists()]
        folder.mkdir(parents=True, exist_ok=True)
        base = f"{time.strftime('%Y%m%d-%H%M%S')}_{label}_seed{seed}"
        for attempt in range(1000):
            path = folder / (base if attempt == 0 else f"{base}-{attempt + 1}")
            try:
                path.mkdir()
            except FileExistsError:
                continue
            run = cls(path, made_parents=made)
            try:
                run.lock()
            except RunFolderError:  # a process that made the same name and locked it first
                continue
            return run
        raise RunFolderError(f"cannot create a new run folder in {folder}")

    @classmethod
    def existing(cls, path: str | Path) -> RunFolder:
        path = Path(path)
        if not (path / "config.json").is_file() or not (path / "checkpoint.npz").is_file():
            raise RunFolderError(f"--resume {path}: not a run folder (needs config.json and checkpoint.npz)")
        return cls(path)

    @property
    def name(self) -> str:
        return self.path.name

    def lock(self) -> None:
        """Hold ``.lock`` (flock, exclusive) until this process exits; refuse a folder another process holds."""
        try:
            descriptor = _open_lock(self.path / LOCK_FILE, os.O_RDWR | os.O_CREAT)
        except OSError as error:
            raise RunFolderError(f"cannot lock {self.path}: {error.strerror or error}") from None
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(descriptor)
            raise RunFolderError(f"{self.path} is in use by another process (it holds {self.path / LOCK_FILE}); "
                                 "wait for it to end, or stop it first") from None
        _HELD_LOCKS.append(descriptor)  # closed, so released, when the process exits

    def remove_if_unused(self) -> None:
        """Remove a folder this process created and that holds nothing but its lock (a start that failed),
        and the folders above it that creating it made."""
        if all(path.name == LOCK_FILE for path in self.path.iterdir()):
            (self.path / LOCK_FILE).unlink(missing_ok=True)
            self.path.rmdir()
            self._remove_made_parents()

    def remove_unstarted(self) -> None:
        """Remove a folder this process created for a run that never started (its config.json was never
        written): its lock and what a logger wrote there while failing to start (MLflow's database, W&B's
        folder); and the folders above it that creating it made."""
        if (self.path / "config.json").exists():
            return
        shutil.rmtree(self.path, ignore_errors=True)
        if not self.path.exists():
            self._remove_made_parents()

    def _remove_made_parents(self) -> None:
        for parent in self.made_parents:  # innermost first; one another process has used meanwhile stays
            try:
                parent.rmdir()
            except OSError:
                break

    def check_resumable(self, es: ESSettings, obs_norm: bool) -> Checkpoint:
        """Refuse, reading only, a checkpoint that does not fit the settings of config.json or its own
        parts, or a folder another process holds (see the module docstring); the checkpoint, checked."""
        if _locked_elsewhere(self.path / LOCK_FILE):
            raise RunFolderError(f"{self.path} is in use by another process (it holds {self.path / LOCK_FILE}); "
                                 "wait for it to end, or stop it first")
        checkpoint = read_checkpoint(self.path / "checkpoint.npz")
        check_checkpoint(checkpoint, es, obs_norm, self.path / "checkpoint.npz")
        recorded = self.read_config().get("num_params")  # what the policy of config.json has (written at the start)
        if isinstance(recorded, int) and checkpoint.theta.size != recorded:
            raise RunFolderError(f"cannot resume from {self.path / 'checkpoint.npz'}: it holds {checkpoint.theta.size} "
                                 f"parameters, and config.json's policy has {recorded}")
        check_metrics(self.read_metrics(checkpoint.generation), checkpoint.generation, self.path / "metrics.csv")
        return checkpoint

    def write(self, write: Callable, name: str, *args) -> None:
        """``write(path / name, *args)``; an OSError becomes a SaveError naming the file."""
        target = self.path / name
        try:
            write(target, *args)
        except OSError as error:
            raise SaveError(f"cannot write {target}: {error.strerror or error}") from None

    # --- parameters ---------------------------------------------------------------------------

    def save_generation(self, policy, state: ESState, history: History, label: str, popsize: int,
                        observations: RunningStat | None = None) -> None:
        """The original's files of the generation just done (named by the policy), best/last, the
        fitness log, and with ``observations`` the statistics beside the weight files of each; the
        checkpoint is written separately, last."""
        reward = reward_label(float(history.metrics[-1]["fitness_mean"]) if history.metrics else math.nan)
        arrays = policy.export(state.theta)
        names = {role: policy.file_name(role, label, reward, popsize, state.generation - 1) for role in arrays}
        self.save_parameters({names[role]: array for role, array in arrays.items()})
        self.save_named("last", arrays)
        weight_role = policy.roles[0]  # the file evaluate_*.py is given: static weights, Hebbian coefficients
        if observations is not None:
            for name in (names[weight_role], named_file("last", weight_role)):
                self.save_statistics(name, observations, policy.obs_clip)
        if history.best_theta is not None:
            self.save_named("best", policy.export(history.best_theta))
            if history.best_observations is not None:
                self.save_statistics(named_file("best", weight_role), history.best_observations, policy.obs_clip)
        self.save_fitness_log(label, history.fitness_log)

    def save_statistics(self, weight_file: str, observations: RunningStat, clip: float | None) -> None:
        """``<weight file>.obs_norm.npz``: the observation statistics to evaluate that file with."""
        self.write(files.atomic_write_bytes, statistics_path(weight_file).name, statistics_bytes(observations, clip))

    def save_parameters(self, named_arrays: dict[str, np.ndarray]) -> None:
        for name, array in named_arrays.items():
            self.write(files.save_dat, name, array)

    def save_named(self, prefix: str, arrays: dict[str, np.ndarray]) -> None:
        """``best``/``last`` copies: one file per role of the policy's export."""
        self.save_parameters({named_file(prefix, role): array for role, array in arrays.items()})

    def named_path(self, prefix: str, role: str) -> Path:
        return self.path / named_file(prefix, role)

    def save_fitness_log(self, env_label: str, log: list[float]) -> None:
        """float32, as the original's (a numpy array of its float32 rewards)."""
        self.write(files.save_npy, fitness_file_name(self.name, env_label), np.array(log, dtype=np.float32))

    # --- config and metrics -------------------------------------------------------------------

    def read_config(self) -> dict:
        data = files.read_json(self.path / "config.json")
        if not isinstance(data, dict):
            raise RunFolderError(f"--resume {self.path}: config.json is not a JSON object")
        return data

    def write_config(self, data: dict) -> None:
        self.write(files.write_json, "config.json", data)

    def write_metrics(self, rows: list[dict], extra_columns: tuple[str, ...] = ()) -> None:
        self.write(files.write_metrics, "metrics.csv", rows, extra_columns)

    def read_metrics(self, up_to_generation: int) -> list[dict]:
        """The rows up to a generation; rows a kill left after the checkpoint are dropped, and so is a
        damaged row (cut short, or with fields too many) after them. A damaged row at or before the
        checkpoint's generation is refused: it is never kept, half empty."""
        path = self.path / "metrics.csv"
        if not path.exists():
            return []
        try:
            rows, damaged = files.read_whole_metrics(path)
            kept = [row for row in rows if int(row["generation"]) <= up_to_generation]
        except files.FileFormatError as error:  # not a regular file
            raise RunFolderError(f"cannot resume: {error}; put the run's own metrics.csv back") from None
        except (KeyError, ValueError, TypeError) as error:
            raise RunFolderError(f"cannot resume: {path} is unreadable ({type(error).__name__}: {error})") from None
        if damaged is not None and up_to_generation not in [0, *(int(row["generation"]) for row in rows)]:
            raise RunFolderError(f"cannot resume: {path} is damaged at line {damaged} (a row cut short, or with fields "
                                 f"too many), before the row of generation {up_to_generation}, the checkpoint's; "
                                 "restore the run's own metrics.csv")
        return kept

    # --- checkpoint ---------------------------------------------------------------------------

    def save_checkpoint(self, checkpoint: Checkpoint) -> None:
        """checkpoint.npz, recording the settings it is written under (``settings``)."""
        checkpoint = replace(checkpoint, settings=self.settings,
                             settings_digest=settings_digest(self.settings) if self.settings else "")
        self.write(files.atomic_write_bytes, "checkpoint.npz", checkpoint.to_bytes())
        self.checkpoint_generation = checkpoint.generation

    def load_checkpoint(self) -> Checkpoint:
        checkpoint = read_checkpoint(self.path / "checkpoint.npz")
        self.checkpoint_generation = checkpoint.generation
        self._remove_stale_temporaries()
        return checkpoint

    def _remove_stale_temporaries(self) -> None:
        """Delete the temporary files and folders of saves that a kill cut short (``es.files``:
        ``.<name>.*.tmp``)."""
        for path in self.path.glob(".*.tmp"):
            if path.is_dir():
                shutil.rmtree(path, ignore_errors=True)
            else:
                path.unlink(missing_ok=True)


def read_checkpoint(path: Path) -> Checkpoint:
    try:
        return Checkpoint.from_file(path)
    except Exception as error:  # truncated, corrupt, or not a checkpoint at all
        raise RunFolderError(f"cannot resume from {path}: not a readable checkpoint "
                             f"({type(error).__name__}); its run cannot be continued") from None


def latest_run(folder: Path) -> Path | None:
    """The newest run folder with a checkpoint in ``folder`` (a run folder's name starts with its time)."""
    runs = sorted(path.parent for path in Path(folder).glob("*/checkpoint.npz"))
    return runs[-1] if runs else None


def generations_done(run_dir: Path | None) -> int:
    """The generations a run folder's checkpoint holds (0 for no run)."""
    return 0 if run_dir is None else read_checkpoint(run_dir / "checkpoint.npz").generation


_HELD_LOCKS: list[int] = []


def release_locks() -> None:
    """Release the run folders this process holds (at the end of a script's run; exiting does it too)."""
    while _HELD_LOCKS:
        os.close(_HELD_LOCKS.pop())


def _open_lock(path: Path, flags: int) -> int:
    """A descriptor of the lock file at ``path``; an OSError if it is not a regular file (a named pipe, whose
    opening would block, is opened without blocking, then refused)."""
    descriptor = os.open(path, flags | os.O_NONBLOCK, 0o644)
    if not stat.S_ISREG(os.fstat(descriptor).st_mode):
        os.close(descriptor)
        raise OSError(errno.EINVAL, f"{path} is not a regular file; remove it")
    return descriptor


def _locked_elsewhere(path: Path) -> bool:
    """Whether another process holds the lock at ``path`` (tested with a shared lock, released at once)."""
    try:
        descriptor = _open_lock(path, os.O_RDONLY)
    except FileNotFoundError:
        return False
    except OSError as error:
        raise RunFolderError(f"cannot lock {path.parent}: {error.strerror or error}") from None
    try:
        fcntl.flock(descriptor, fcntl.LOCK_SH | fcntl.LOCK_NB)
        return False
    except OSError:
        return True
    finally:
        os.close(descriptor)


def check_checkpoint(checkpoint: Checkpoint, es: ESSettings, obs_norm: bool, path: Path) -> None:
    """Its numbers are finite, its sizes agree, and its optimiser and observation state are those of the
    run's settings; else a RunFolderError naming what differs."""
    def refuse(problem: str):
        raise RunFolderError(f"cannot resume from {path}: {problem}; the checkpoint does not belong to this run's "
                             "config.json, or was damaged")

    dim = checkpoint.theta.size
    if checkpoint.theta.ndim != 1 or dim == 0:
        refuse(f"theta has shape {checkpoint.theta.shape}, not a vector of parameters")
    if checkpoint.generation < 0:
        refuse(f"generation {checkpoint.generation} is negative")
    if len(checkpoint.fitness_log) > checkpoint.generation:  # one per save at a multiple of --print_every
        refuse(f"it has {len(checkpoint.fitness_log)} fitness values for {checkpoint.generation} generations")
    if checkpoint.settings and settings_digest(checkpoint.settings) != checkpoint.settings_digest:
        refuse("its record of the run's settings does not match its digest")
    if checkpoint.best_theta.size not in (0, dim):
        refuse(f"best_theta has {checkpoint.best_theta.size} values, theta {dim}")
    for name in ("lr", "sigma"):
        if not (math.isfinite(getattr(checkpoint, name)) and getattr(checkpoint, name) > 0):
            refuse(f"{name} is {getattr(checkpoint, name)}, not a positive number")
    if checkpoint.total_steps < 0 or not math.isfinite(checkpoint.total_seconds):
        refuse(f"total_steps {checkpoint.total_steps} or total_seconds {checkpoint.total_seconds} is impossible")
    for name, array in _arrays(checkpoint):
        if not np.issubdtype(array.dtype, np.number) or not np.isfinite(array).all():
            refuse(f"{name} holds {'NaN or infinite values' if np.issubdtype(array.dtype, np.number) else array.dtype}")
    _check_optimizer_state(checkpoint, es, refuse)
    _check_observations(checkpoint, obs_norm, refuse)


def _arrays(checkpoint: Checkpoint) -> list[tuple[str, np.ndarray]]:
    """The arrays the run goes on from (the fitness log is only a record: a failed episode may be NaN)."""
    found = [("theta", checkpoint.theta), ("best_theta", checkpoint.best_theta)]
    for group in ("optimizer", "strategy", "observations", "best_observations"):
        found += [(f"{group}.{key}", np.asarray(array)) for key, array in getattr(checkpoint, group).items()]
    return found


def _check_optimizer_state(checkpoint: Checkpoint, es: ESSettings, refuse: Callable) -> None:
    """The keys the run's optimiser keeps (those one step from nothing makes), each of theta's size but
    for counters; a generation-0 checkpoint has none yet."""
    if es.strategy != "openai":  # another strategy keeps its own state, checked when it is restored
        return
    dim = checkpoint.theta.size
    zeros = np.zeros(dim, np.float32)
    _, fresh = make_optimizer(es).step(zeros, zeros.astype(np.float64), 2, 1.0, 1.0, {})
    state = checkpoint.optimizer
    if set(state) != set(fresh) and (state or checkpoint.generation > 0):
        refuse(f"its optimiser state ({', '.join(sorted(state)) or 'none'}) is not that of --optimizer "
               f"{es.optimizer} ({', '.join(sorted(fresh)) or 'none'})")
    for key, array in state.items():
        expected = np.shape(fresh.get(key))
        if np.shape(array) != expected:
            refuse(f"optimizer.{key} has shape {np.shape(array)}, not {expected}")


def _check_observations(checkpoint: Checkpoint, obs_norm: bool, refuse: Callable) -> None:
    for group in ("observations", "best_observations"):
        arrays = getattr(checkpoint, group)
        if arrays and not obs_norm:
            refuse(f"it holds {group} statistics, and config.json says the run does not normalise observations")
        if not arrays:
            continue
        if set(arrays) != {"sum", "sumsq", "count"} or np.shape(arrays["sum"]) != np.shape(arrays["sumsq"]) \
                or np.ndim(arrays["count"]) != 0 or float(arrays["count"]) <= 0 or (arrays["sumsq"] < 0).any():
            refuse(f"its {group} statistics are not a running mean (sum, sumsq, count > 0 of one shape)")
    if obs_norm and not checkpoint.observations and checkpoint.generation > 0:
        refuse("config.json says the run normalises observations, and the checkpoint holds no statistics")


def check_metrics(rows: list[dict], generation: int, path: Path) -> None:
    """metrics.csv holds one row for each generation up to the checkpoint's, in order."""
    numbers = [int(float(row["generation"])) for row in rows]
    if numbers != list(range(1, generation + 1)):
        raise RunFolderError(f"cannot resume: {path} holds generations {numbers[:3]}{'...' if len(numbers) > 3 else ''}"
                             f" where the checkpoint has run {generation}; restore the run's own metrics.csv")


LABEL_DIGITS = 15  # a float64 holds 15 significant digits: an integer part longer than that is noise


def reward_label(mean_fitness: float) -> int | str:
    """The ``rew_`` part of the original file names: int of the mean fitness (0 if not finite), as the
    original; beyond 15 digits its three leading digits and exponent (``-1.71e+308``), so that a name
    stays short whatever the reward."""
    if not math.isfinite(mean_fitness):
        return 0
    return int(mean_fitness) if abs(mean_fitness) < 10**LABEL_DIGITS else f"{mean_fitness:.3g}"
