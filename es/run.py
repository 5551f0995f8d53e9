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

from es import files, plots
from es.evaluator import EvaluationError, ProcessEvaluator, Results, SerialEvaluator, WorkerStartError
from es.noise import NoiseTable, default_size
from es.progress import Display, QuietDisplay
from es.strategy import ESState, OpenES
from es.worker import make_tasks, perturb

L2_COEFF = 0.01
SEED_LIMIT = 2**31 - 1
FAILED = 1
INTERRUPTED = 130
RAY_INSTALL_HINT = "install it with: pip install -r requirements-ray.txt (or pip install -e .[ray])"


class UserError(ValueError):
    """A problem the user can fix (bad value, missing file); reported in one line, exit code 2."""


class SaveError(RuntimeError):
    """A file of the run could not be written (disk full, folder made read-only); names the file."""


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
    ray_address: str | None = None  # --backend ray: None starts a local Ray
    hebb_rule: str = "ABCD_lr"
    init_weights: str = "uni"
    distribution: str = "normal"
    noise_size: int | None = None  # default: sized to the parameter count

    @property
    def workers(self) -> int:
        return (os.cpu_count() or 1) if self.threads == -1 else self.threads

    @property
    def env_label(self) -> str:
        """The environment part of the original file names: the ids as given, joined by '+',
        without the ``module:`` part of custom ids (a colon is not portable in file names)."""
        return "+".join(part.strip().rpartition(":")[2] for part in self.environment.split(",") if part.strip())

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
    """First Ctrl-C (or SIGTERM, as a cluster scheduler sends): finish the generation, save, stop.
    A second one: stop at once."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self.requested = False
        self._previous: dict = {}

    def __enter__(self):
        self._previous = {signum: signal.signal(signum, self._handle) for signum in self.SIGNALS}
        return self

    def __exit__(self, *exc):
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)

    def _handle(self, signum, frame):
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        name = "interrupt" if signum == signal.SIGINT else signal.Signals(signum).name
        print(f"\n{name}: finishing this generation, then saving (Ctrl-C again to stop at once)",
              file=sys.stderr, flush=True)


@dataclass
class History:
    """What a run has done so far, beyond the strategy state: saved in the checkpoint."""

    best_theta: np.ndarray | None = None
    best_center: float = -math.inf
    fitness_log: list[float] = field(default_factory=list)  # the original's Fitness_values file
    metrics: list[dict] = field(default_factory=list)
    total_steps: int = 0
    total_seconds: float = 0.0


class Run:
    """Owns the run folder, the strategy state and the evaluator for one training run."""

    def __init__(self, config: TrainConfig, spec, run_dir: Path, log: Callable[[str], None] = print,
                 display: Display | None = None):
        self.config, self.spec, self.run_dir, self.log = config, spec, Path(run_dir), log
        self.display = display or QuietDisplay()  # the live progress line (es.progress)
        self.checkpoint_generation: int | None = None  # the generation the checkpoint file holds
        problem = spec.build()
        self.policy = problem.policy
        self.dim = self.policy.num_params
        self.strategy = OpenES(config.popsize, config.decay)
        self.noise_size = config.noise_size or default_size(self.dim)
        config.noise_size = self.noise_size
        # in this process for --threads 1, or a one-core machine's pool; Ray counts its cluster's CPUs
        serial = config.threads == 1 or (config.backend == "process" and config.workers == 1)
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
        self.history = History()
        self.state = ESState(self.policy.initial_params(np.random.default_rng([config.seed, 1]),
                                                        config.distribution),
                             config.lr, config.sigma, 0)

    # --- the loop -----------------------------------------------------------------------------

    def train(self) -> int:
        """Run generations up to ``config.generations``; the exit code: 0, FAILED or INTERRUPTED."""
        with _Interrupts() as interrupts:
            try:
                while self.state.generation < self.config.generations:
                    self._generation()
                    if self._save_due() or interrupts.requested:
                        self.save()
                    if interrupts.requested:
                        self.log(f"interrupted after generation {self.state.generation}; "
                                 f"resume with: {self.resume_hint()}")
                        return INTERRUPTED
            except (EvaluationError, WorkerStartError, SaveError) as error:
                return self._stop(error)
        return 0

    def _save_due(self) -> bool:
        generation = self.state.generation
        return generation % self.config.print_every == 0 or generation == self.config.generations

    def _stop(self, error: EvaluationError | WorkerStartError | SaveError) -> int:
        """Report what stopped the run, checkpoint it if that still works, and say how to resume."""
        self.log(f"error: {error}")
        if not isinstance(error, SaveError):  # a failed save would most likely fail again
            try:
                self.save_checkpoint()
            except SaveError as save_error:
                self.log(f"error: {save_error}")
        if self.checkpoint_generation is None:
            self.log("stopped; no checkpoint could be written")
        else:
            self.log(f"stopped; the checkpoint holds generation {self.checkpoint_generation}; "
                     f"resume with: {self.resume_hint()}")
        return FAILED

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
        results = self._evaluate(tasks)
        returns = results.returns.reshape(population + 1, -1).mean(axis=1)
        member_returns, center_return = returns[:population], float(returns[population])
        fitness = member_returns - L2_COEFF * l2_penalties(state.theta, self.noise, indices, signs,
                                                           state.sigma, policy.penalised)
        finite = np.isfinite(fitness)
        fitness[~finite] = -np.inf  # NaN or infinite returns are ranked last, never stepped on
        self.state, info = self.strategy.tell(state, self.noise, indices, fitness)
        if np.isfinite(center_return) and center_return > self.history.best_center:
            self.history.best_center, self.history.best_theta = center_return, state.theta
        self._record(fitness[finite], member_returns[finite], center_return, info,
                     int((~finite).sum()), int(results.steps.sum()), time.perf_counter() - started)

    def _evaluate(self, tasks: np.ndarray) -> Results:
        """The generation's episodes, under the live progress line; retried failures are reported."""
        state = self.state
        generations_after = self.config.generations - state.generation - 1
        with self.display.generation(state.generation + 1, len(tasks), generations_after) as progress:
            results = self.evaluator.evaluate(state.generation, state.theta, state.sigma, tasks, progress=progress)
        for message in results.retried:
            self.log(f"warning: {message}")
        return results

    def _record(self, fitness, returns, center_return, info, nonfinite, steps, seconds):
        """Append the generation's metrics row, rewrite metrics.csv, print the generation's line."""
        history, after = self.history, self.state
        history.total_steps += steps
        history.total_seconds += seconds

        def stat(values: np.ndarray, reduce) -> float:  # finite values only; NaN if there are none
            return float(reduce(values)) if values.size else math.nan

        mean = stat(fitness, np.mean)
        row = dict(generation=after.generation, fitness_mean=mean, fitness_max=stat(fitness, np.max),
                   fitness_min=stat(fitness, np.min), fitness_std=stat(fitness, np.std),
                   return_mean=stat(returns, np.mean), center_return=center_return, sigma=after.sigma, lr=after.lr,
                   update_factor=info["update_factor"], skipped=int(info["skipped"]), nonfinite=nonfinite,
                   env_steps=steps, total_env_steps=history.total_steps, seconds=round(seconds, 3),
                   total_seconds=round(history.total_seconds, 3))
        history.metrics.append(row)
        if after.generation % self.config.print_every == 0:
            history.fitness_log.append(mean)
        self._write(files.write_metrics, "metrics.csv", history.metrics)
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
        """The original's files for this generation, best/last, the fitness log and picture, and
        last the checkpoint: a save cut short leaves the previous checkpoint to resume from."""
        history, state = self.history, self.state
        mean = float(history.metrics[-1]["fitness_mean"]) if history.metrics else math.nan
        reward = int(mean) if np.isfinite(mean) else 0
        for name, array in self.original_files(state.theta, reward, state.generation - 1).items():
            self._write(files.save_dat, name, array)
        self._save_named("last", state.theta)
        if history.best_theta is not None:
            self._save_named("best", history.best_theta)
        run_id = self.run_dir.name
        self._write(files.save_npy, files.fitness_file_name(run_id, self.config.env_label),
                    np.array(history.fitness_log))
        self._write(plots.save_run_plot, "fitness.png", history.metrics, run_id)
        self.save_checkpoint()

    def _save_named(self, prefix: str, theta: np.ndarray) -> None:
        arrays = self.policy.export(theta)
        for role, array in arrays.items():
            self._write(files.save_dat, files.named_file(prefix, role), array)

    def _write(self, write: Callable, name: str, *args) -> None:
        """``write(run_dir / name, *args)``; an OSError becomes a SaveError naming the file.

        Every writer in ``es.files`` is atomic, so a failed write leaves the earlier file whole.
        """
        path = self.run_dir / name
        try:
            write(path, *args)
        except OSError as error:
            raise SaveError(f"cannot write {path}: {error.strerror or error}") from None

    def save_checkpoint(self) -> None:
        state, history = self.state, self.history
        buffer = io.BytesIO()
        np.savez(buffer, theta=state.theta, lr=state.lr, sigma=state.sigma, generation=state.generation,
                 best_theta=history.best_theta if history.best_theta is not None else np.zeros(0, np.float32),
                 best_center=history.best_center, fitness_log=np.array(history.fitness_log),
                 total_steps=history.total_steps, total_seconds=history.total_seconds)
        self._write(files.atomic_write_bytes, "checkpoint.npz", buffer.getvalue())
        self.checkpoint_generation = state.generation

    def load_checkpoint(self) -> None:
        """Continue from the run folder's checkpoint; metrics rows after it are dropped."""
        path = self.run_dir / "checkpoint.npz"
        try:
            with np.load(path) as file:
                saved = {name: file[name] for name in file.files}
            theta, best = saved["theta"], saved["best_theta"]
            state = ESState(theta.astype(np.float32), float(saved["lr"]), float(saved["sigma"]),
                            int(saved["generation"]))
            history = History(best if best.size else None, float(saved["best_center"]),
                              [float(value) for value in saved["fitness_log"]], [],
                              int(saved["total_steps"]), float(saved["total_seconds"]))
        except Exception as error:  # truncated, corrupt, or not a checkpoint at all
            raise UserError(f"cannot resume from {path}: not a readable checkpoint "
                            f"({type(error).__name__}); its run cannot be continued") from None
        if theta.shape != (self.dim,):
            raise UserError(f"{path} holds {theta.size} parameters; this run needs {self.dim}")
        self.state, self.history = state, history
        metrics_path = self.run_dir / "metrics.csv"
        try:
            rows = files.read_metrics(metrics_path) if metrics_path.exists() else []
            self.history.metrics = [row for row in rows if int(row["generation"]) <= self.state.generation]
        except (KeyError, ValueError, TypeError) as error:
            raise UserError(f"cannot resume: {metrics_path} is unreadable ({type(error).__name__}: {error})") from None
        self.checkpoint_generation = self.state.generation
        self._remove_stale_temporaries()

    def _remove_stale_temporaries(self) -> None:
        """Delete the temporary files of saves that a kill cut short (``es.files``: ``.<name>.*.tmp``)."""
        for path in self.run_dir.glob(".*.tmp"):
            path.unlink(missing_ok=True)

    def resume_hint(self) -> str:
        script = "train_hebb.py" if self.config.kind == "hebbian" else "train_static.py"
        return f"python {script} --resume {self.run_dir}"

    def evaluate_hint(self) -> str:
        """The command that evaluates this run's final parameters over 10 episodes.

        Not ``best``: that is the centre with the best single-episode return, a noisy choice.
        """
        config = self.config
        paths = {role: self.run_dir / files.named_file("last", role) for role in self.policy.export(self.state.theta)}
        if config.kind == "static":
            return (f"python evaluate_static.py --environment {config.environment} "
                    f"--path_weights {paths['weights']} --episodes 10")
        coevolved = "".join(f" --path_coev {path}" for role, path in paths.items() if role != "coeffs")
        return (f"python evaluate_hebb.py --environment {config.environment} --hebb_rule {config.hebb_rule} "
                f"--init_weights {config.init_weights} --path_hebb {paths['coeffs']}{coevolved} --episodes 10")

    def write_config(self, argv: list[str]) -> None:
        """config.json; a resume keeps the first command and lists its own under "resumed"."""
        data = asdict(self.config)
        path = self.run_dir / "config.json"
        earlier = files.read_json(path) if path.exists() else {}
        command = " ".join(argv)
        resumed = earlier.get("resumed", []) + ([command] if earlier else [])
        data.update(command=earlier.get("command", command), resumed=resumed, versions=versions(),
                    num_params=self.dim, layout=self.policy.layout.describe(), workers=self.evaluator.workers)
        self._write(files.write_json, "config.json", data)

    def close(self) -> None:
        self.evaluator.close()
        self.noise.close()


def make_parallel_evaluator(config: TrainConfig, spec, noise: NoiseTable, dim: int, env_ids: tuple[str, ...]):
    """The evaluator of ``config.backend`` for ``config.workers`` > 1."""
    if config.backend == "process":
        return ProcessEvaluator(spec.build, noise, dim, env_ids, config.workers)
    if config.backend == "ray":
        try:
            from es.ray_backend import RayEvaluator
        except ModuleNotFoundError as error:
            if error.name != "ray":
                raise
            raise UserError(f"--backend ray needs Ray, which is not installed; {RAY_INSTALL_HINT}") from None
        workers = None if config.threads == -1 else config.threads  # -1: one per CPU Ray reports
        return RayEvaluator(spec.build, noise, dim, env_ids, workers, config.ray_address)
    raise UserError(f"unknown backend {config.backend!r}; valid backends: process, ray")


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
