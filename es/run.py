"""A training run: the generation loop, its log line, its files, checkpoints and resume.

One generation (DESIGN.md, "Data flow"):

    ask (noise indices, signs) -> tasks (member, index, sign, env, seed) -> evaluator
    -> returns in member order -> fitness = mean return - 0.01 * mean(theta_m^2) -> tell -> log, save

All randomness of generation g comes from ``generation_rng(seed, g)``, and the noise table and
theta_0 from the seed alone, so a run is a pure function of its settings: the same seed gives the
same theta with any number of workers, and a resumed run continues exactly where it stopped.
"""

from __future__ import annotations

import io
import math
import os
import signal
import sys
import time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Callable

import numpy as np

from es import files
from es.evaluator import EvaluationError, ProcessEvaluator, SerialEvaluator
from es.noise import NoiseTable, default_size
from es.strategy import ESState, OpenES
from es.worker import make_tasks, perturb

L2_COEFF = 0.01
SEED_LIMIT = 2**31 - 1
INTERRUPTED = 130


class UserError(ValueError):
    """A problem the user can fix (bad value, missing file); reported in one line, exit code 2."""


@dataclass
class TrainConfig:
    kind: str  # "static" or "hebbian"
    environment: str  # as given on the command line (comma-separated list)
    env_ids: list[str]  # the registered ids actually made
    popsize: int = 200
    lr: float = 0.2
    decay: float = 0.995
    sigma: float = 0.1
    generations: int = 300
    print_every: int = 1
    folder: str = "weights"
    threads: int = -1
    seed: int = 0
    episodes: int = 1
    backend: str = "process"
    hebb_rule: str = "ABCD_lr"
    init_weights: str = "uni"
    distribution: str = "normal"
    noise_size: int | None = None  # default: sized to the parameter count
    extra: dict = field(default_factory=dict)  # anything a front-end wants recorded

    @property
    def workers(self) -> int:
        return (os.cpu_count() or 1) if self.threads == -1 else self.threads

    @property
    def env_label(self) -> str:
        """The environment part of the original file names (several envs joined by '+')."""
        return "+".join(part.strip() for part in self.environment.split(","))

    @classmethod
    def from_dict(cls, data: dict) -> "TrainConfig":
        names = {f.name for f in fields(cls)}
        return cls(**{key: value for key, value in data.items() if key in names})


def generation_rng(seed: int, generation: int) -> np.random.Generator:
    return np.random.default_rng([seed, 2, generation])


def l2_penalties(theta: np.ndarray, noise: NoiseTable, indices: np.ndarray, signs: np.ndarray,
                 sigma: float, penalised: slice) -> np.ndarray:
    """mean(theta_m^2) over the penalised part of every member's parameters."""
    dim = theta.size
    part = theta[penalised]
    return np.array([np.mean(np.square(perturb(part, noise.slice(index, dim)[penalised], sign, sigma),
                                       dtype=np.float64))
                     for index, sign in zip(indices, signs)])


def versions() -> dict:
    import importlib.metadata as metadata

    found = {"python": sys.version.split()[0]}
    for package in ("numpy", "torch", "gymnasium", "mujoco", "pybullet", "pybullet-envs-gymnasium",
                    "box2d", "numba", "ray"):
        try:
            found[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            pass
    return found


class _Interrupts:
    """First Ctrl-C: finish the generation, save, stop. Second: stop at once."""

    def __init__(self):
        self.requested = False
        self._previous = None

    def __enter__(self):
        self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc):
        signal.signal(signal.SIGINT, self._previous)

    def _handle(self, signum, frame):
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        print("\ninterrupt: finishing this generation, then saving (Ctrl-C again to stop at once)",
              file=sys.stderr, flush=True)


@dataclass
class Progress:
    best_theta: np.ndarray | None = None
    best_center: float = -math.inf
    fitness_log: list[float] = field(default_factory=list)  # the original's Fitness_values file
    metrics: list[dict] = field(default_factory=list)
    total_steps: int = 0
    total_seconds: float = 0.0


class Run:
    """Owns the run folder, the strategy state and the evaluator for one training run."""

    def __init__(self, config: TrainConfig, spec, run_dir: Path, log: Callable[[str], None] = print):
        self.config, self.spec, self.run_dir, self.log = config, spec, Path(run_dir), log
        problem = spec.build()
        self.policy = problem.policy
        self.dim = self.policy.num_params
        self.strategy = OpenES(config.popsize, config.decay)
        self.noise_size = config.noise_size or default_size(self.dim)
        config.noise_size = self.noise_size
        serial = config.workers == 1
        self.noise = NoiseTable.create(config.seed, self.noise_size, shared=not serial)
        try:
            env_ids = tuple(config.env_ids)
            if serial:
                self.evaluator = SerialEvaluator(lambda: problem, self.noise, self.dim, env_ids)
            else:
                problem.close()
                self.evaluator = make_parallel_evaluator(config, spec, self.noise, self.dim, env_ids)
        except BaseException:
            self.noise.close()
            raise
        self.progress = Progress()
        self.state = ESState(self.policy.initial_params(np.random.default_rng([config.seed, 1]),
                                                        config.distribution),
                             config.lr, config.sigma, 0)

    # --- the loop -----------------------------------------------------------------------------

    def train(self) -> int:
        config = self.config
        with _Interrupts() as interrupts:
            while self.state.generation < config.generations:
                try:
                    self._generation()
                except EvaluationError as error:
                    self.save_checkpoint()
                    self.log(f"error: {error}")
                    self.log(f"stopped; the last checkpoint is in {self.run_dir} ({self.resume_hint()})")
                    return 1
                generation = self.state.generation
                if generation % config.print_every == 0 or generation == config.generations or interrupts.requested:
                    self.save()
                if interrupts.requested:
                    self.log(f"interrupted after generation {generation}; resume with: {self.resume_hint()}")
                    return INTERRUPTED
        return 0

    def _generation(self) -> None:
        config, state, policy = self.config, self.state, self.policy
        started = time.perf_counter()
        rng = generation_rng(config.seed, state.generation)
        indices, signs = self.strategy.ask(rng, self.noise, self.dim)
        pair_seeds = rng.integers(0, SEED_LIMIT, size=(self.strategy.pairs, config.episodes))
        center_seeds = rng.integers(0, SEED_LIMIT, size=(1, config.episodes))
        population = config.popsize
        tasks = make_tasks(np.arange(population + 1), np.append(indices, -1), np.append(signs, 0),
                           np.concatenate([np.repeat(pair_seeds, 2, axis=0), center_seeds]),
                           len(config.env_ids))
        results = self.evaluator.evaluate(state.generation, state.theta, state.sigma, tasks)
        returns = results.returns.reshape(population + 1, -1).mean(axis=1)
        member_returns, center_return = returns[:population], float(returns[population])
        fitness = member_returns - L2_COEFF * l2_penalties(state.theta, self.noise, indices, signs,
                                                           state.sigma, policy.penalised)
        finite = np.isfinite(fitness)
        fitness[~finite] = -np.inf  # NaN or infinite returns are ranked last, never stepped on
        self.state, info = self.strategy.tell(state, self.noise, indices, fitness)
        if np.isfinite(center_return) and center_return > self.progress.best_center:
            self.progress.best_center, self.progress.best_theta = center_return, state.theta
        self._record(state, fitness[finite], member_returns[finite], center_return, info,
                     int((~finite).sum()), int(results.steps.sum()), time.perf_counter() - started)

    def _record(self, before: ESState, fitness, returns, center_return, info, nonfinite, steps, seconds):
        progress, after = self.progress, self.state
        progress.total_steps += steps
        progress.total_seconds += seconds
        mean = float(fitness.mean()) if fitness.size else math.nan
        row = dict(generation=after.generation, fitness_mean=mean,
                   fitness_max=float(fitness.max()) if fitness.size else math.nan,
                   fitness_min=float(fitness.min()) if fitness.size else math.nan,
                   fitness_std=float(fitness.std()) if fitness.size else math.nan,
                   return_mean=float(returns.mean()) if returns.size else math.nan,
                   center_return=center_return, sigma=after.sigma, lr=after.lr,
                   update_factor=info["update_factor"], skipped=int(info["skipped"]), nonfinite=nonfinite,
                   env_steps=steps, total_env_steps=progress.total_steps, seconds=round(seconds, 3),
                   total_seconds=round(progress.total_seconds, 3))
        progress.metrics.append(row)
        if after.generation % self.config.print_every == 0:
            progress.fitness_log.append(mean)
        files.write_metrics(self.run_dir / "metrics.csv", progress.metrics)
        self.log(self._line(row, after))

    def _line(self, row: dict, after: ESState) -> str:
        hebbian = self.config.kind == "hebbian"
        coefficients = after.theta[self.policy.layout["coefficients"].slice] if hebbian else after.theta
        name = "coeffs" if hebbian else "w"
        line = (f"iter {row['generation']} | reward: {row['fitness_mean']:.3f} | "
                f"update_factor: {row['update_factor']:.6f} | lr: {row['lr']:.6f} | "
                f"sum_{name}: {float(coefficients.sum()):.3f} | "
                f"sum_abs_{name}: {float(np.abs(coefficients).sum()):.3f} | "
                f"center: {row['center_return']:.2f} | steps: {row['env_steps']} | {row['seconds']:.1f}s")
        if row["nonfinite"]:
            line += f" | {row['nonfinite']} non-finite returns ranked last"
        if row["skipped"]:
            line += " | step skipped: all fitness values equal"
        return line

    # --- files --------------------------------------------------------------------------------

    def original_files(self, theta: np.ndarray, reward: int, generation: int) -> dict[str, np.ndarray]:
        """File name -> array, in the original names and shapes."""
        config, arrays = self.config, self.policy.export(theta)
        if config.kind == "static":
            return {files.static_file_name(config.env_label, reward, config.popsize, generation):
                    arrays["weights"]}
        return {files.hebbian_file_name(config.env_label, reward, config.hebb_rule, config.init_weights,
                                        config.popsize, role, generation): array
                for role, array in arrays.items()}

    def save(self) -> None:
        """The original's files for this generation, best/last, the fitness log, the checkpoint."""
        progress, state = self.progress, self.state
        mean = progress.metrics[-1]["fitness_mean"] if progress.metrics else math.nan
        reward = int(mean) if np.isfinite(mean) else 0
        for name, array in self.original_files(state.theta, reward, state.generation - 1).items():
            files.save_dat(self.run_dir / name, array)
        self._save_named("last", state.theta)
        if progress.best_theta is not None:
            self._save_named("best", progress.best_theta)
        run_id = self.run_dir.name
        files.save_npy(self.run_dir / files.fitness_file_name(run_id, self.config.env_label),
                       np.array(progress.fitness_log))
        self.save_checkpoint()

    def _save_named(self, prefix: str, theta: np.ndarray) -> None:
        arrays = self.policy.export(theta)
        for role, array in arrays.items():
            name = f"{prefix}.dat" if role == "weights" else f"{prefix}_{role}.dat"
            files.save_dat(self.run_dir / name, array)

    def save_checkpoint(self) -> None:
        state, progress = self.state, self.progress
        buffer = io.BytesIO()
        np.savez(buffer, theta=state.theta, lr=state.lr, sigma=state.sigma, generation=state.generation,
                 best_theta=progress.best_theta if progress.best_theta is not None else np.zeros(0, np.float32),
                 best_center=progress.best_center, fitness_log=np.array(progress.fitness_log),
                 total_steps=progress.total_steps, total_seconds=progress.total_seconds)
        files.atomic_write_bytes(self.run_dir / "checkpoint.npz", buffer.getvalue())

    def load_checkpoint(self) -> None:
        path = self.run_dir / "checkpoint.npz"
        try:
            with np.load(path) as saved:
                theta = saved["theta"]
                if theta.shape != (self.dim,):
                    raise UserError(f"{path} holds {theta.size} parameters; this run needs {self.dim}")
                self.state = ESState(theta.astype(np.float32), float(saved["lr"]), float(saved["sigma"]),
                                     int(saved["generation"]))
                best = saved["best_theta"]
                self.progress = Progress(best if best.size else None, float(saved["best_center"]),
                                         [float(value) for value in saved["fitness_log"]], [],
                                         int(saved["total_steps"]), float(saved["total_seconds"]))
        except (OSError, KeyError, ValueError) as error:
            if isinstance(error, UserError):
                raise
            raise UserError(f"cannot resume from {path}: {error}") from None
        metrics_path = self.run_dir / "metrics.csv"
        rows = files.read_metrics(metrics_path) if metrics_path.exists() else []
        self.progress.metrics = [row for row in rows if int(row["generation"]) <= self.state.generation]

    def resume_hint(self) -> str:
        script = "train_hebb.py" if self.config.kind == "hebbian" else "train_static.py"
        return f"python {script} --resume {self.run_dir}"

    def write_config(self, argv: list[str]) -> None:
        data = asdict(self.config)
        data.update(command=" ".join(argv), versions=versions(), num_params=self.dim,
                    layout=self.policy.layout.describe(), workers=self.evaluator.workers)
        files.write_json(self.run_dir / "config.json", data)

    def close(self) -> None:
        self.evaluator.close()
        self.noise.close()


def make_parallel_evaluator(config: TrainConfig, spec, noise: NoiseTable, dim: int, env_ids: tuple[str, ...]):
    if config.backend == "process":
        return ProcessEvaluator(spec.build, noise, dim, env_ids, config.workers)
    raise UserError(f"unknown backend {config.backend!r}; valid backends: process")


def new_run_dir(folder: str | Path, label: str, seed: int) -> Path:
    """A fresh run folder ``<folder>/<time>_<env>_seed<seed>``; never an existing one."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    base = f"{stamp}_{label}_seed{seed}"
    for attempt in range(1000):
        path = folder / (base if attempt == 0 else f"{base}-{attempt + 1}")
        try:
            path.mkdir()
            return path
        except FileExistsError:
            continue
    raise UserError(f"cannot create a new run folder in {folder}")
