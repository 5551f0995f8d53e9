"""The generation loop of a training run: ask -> tasks -> evaluate -> fitness -> tell -> record.

All randomness of generation g comes from ``generation_rng(seed, g)``, and the noise table and
theta_0 from the seed alone, so a run is a pure function of its settings: the same seed gives the
same theta with any backend and number of workers, and a resumed run continues exactly where it
stopped. The loop knows arrays, workers and files; the policy only through its protocol
(``num_params``, ``initial_params``, ``penalised``, ``export``, ``file_name``), the environments
not at all; what the user sees goes through the injected ``log``, display and reporters.
"""

from __future__ import annotations

import contextlib
import enum
import math
import time
from dataclasses import replace
from typing import Callable, Protocol, Sequence

import numpy as np

from es.backends import EvaluationError, Evaluator, Generation, WorkerStartError, make_evaluator
from es.interrupts import Interrupts
from es.noise import NoiseTable, default_size
from es.runfolder import Checkpoint, History, RunFolder, SaveError
from es.settings import ESSettings, RunSettings
from es.shaping import penalised_fitness
from es.strategy import OpenES
from es.worker import make_tasks

SEED_LIMIT = 2**31 - 1


class NonFiniteUpdate(RuntimeError):
    """A step that would make theta NaN or infinite (an lr too large, a sigma too small)."""


class Status(enum.Enum):
    DONE = "done"
    INTERRUPTED = "interrupted"  # by Ctrl-C or SIGTERM, after a save
    FAILED = "failed"  # an episode failed twice, a worker could not start, or a file could not be written


def generation_rng(seed: int, generation: int) -> np.random.Generator:
    return np.random.default_rng([seed, 2, generation])


class Reporter(Protocol):
    def generation(self, row: dict) -> None:
        """After every generation, with its metrics row."""

    def saved(self, folder: RunFolder, rows: list[dict]) -> None:
        """After every save of the run's files, with every metrics row so far."""


class Trainer:
    def __init__(self, es: ESSettings, run: RunSettings, policy, noise: NoiseTable, evaluator: Evaluator,
                 n_envs: int, folder: RunFolder, label: str, log: Callable[[str], None] = print,
                 display=None, reporters: Sequence[Reporter] = ()):
        self.es, self.run, self.policy, self.noise, self.evaluator = es, run, policy, noise, evaluator
        self.n_envs, self.folder, self.label, self.log = n_envs, folder, label, log
        self.display, self.reporters = display, reporters
        self.strategy = OpenES(es)
        self.state = self.strategy.initial_state(policy.initial_params(np.random.default_rng([run.seed, 1])))
        self.history = History()
        self.failure: Exception | None = None  # what stopped the run, if something did

    @classmethod
    def start(cls, es: ESSettings, run: RunSettings, problem, build_problem: Callable[[], object],
              env_ids: tuple[str, ...], folder: RunFolder, label: str, **options) -> "Trainer":
        """Noise table and evaluator for ``problem`` (built here, reused by the serial backend)."""
        dim = problem.policy.num_params
        es = replace(es, noise_size=es.noise_size or default_size(dim))
        noise = NoiseTable.create(run.seed, es.noise_size, shared=not run.in_process)
        try:
            evaluator = make_evaluator(run, build_problem, noise, dim, env_ids, problem)
        except BaseException:
            noise.close()
            raise
        return cls(es, run, problem.policy, noise, evaluator, len(env_ids), folder, label, **options)

    def train(self) -> Status:
        """Generations up to ``run.generations``; saves every ``print_every``, at the end and when interrupted."""
        with Interrupts() as interrupts:
            try:
                while self.state.generation < self.run.generations:
                    self.generation()
                    done = self.state.generation
                    if done % self.run.print_every == 0 or done == self.run.generations or interrupts.requested:
                        self.save()
                    if interrupts.requested:
                        return Status.INTERRUPTED
            except (EvaluationError, WorkerStartError, SaveError, NonFiniteUpdate) as error:
                return self._stop(error)
        return Status.DONE

    def generation(self) -> dict:
        """One generation, top to bottom; its metrics row."""
        started, state, popsize = time.perf_counter(), self.state, self.es.popsize
        rng = generation_rng(self.run.seed, state.generation)
        indices, signs = self.strategy.ask(rng, self.noise, self.policy.num_params)
        pair_seeds = rng.integers(0, SEED_LIMIT, size=(popsize // 2, self.es.episodes))
        center_seeds = rng.integers(0, SEED_LIMIT, size=(1, self.es.episodes))
        tasks = make_tasks(np.arange(popsize + 1), np.append(indices, -1), np.append(signs, 0),
                           np.concatenate([np.repeat(pair_seeds, 2, axis=0), center_seeds]), self.n_envs)
        results = self._evaluate(Generation(state.generation, state.theta, state.sigma, tasks))
        returns = results.returns.reshape(popsize + 1, -1).mean(axis=1)  # the centre is the last "member"
        penalties = results.penalties.reshape(popsize + 1, -1)[:, 0]  # equal on every task of a member
        fitness = penalised_fitness(returns[:popsize], penalties[:popsize], self.es.fitness_l2)
        new_state, info = self.strategy.tell(state, self.noise, indices, fitness)
        if not np.isfinite(new_state.theta).all():  # stop where it appears, keeping the last finite theta
            raise NonFiniteUpdate(f"generation {state.generation + 1}: the update is not finite (lr {state.lr:g}, "
                                  f"sigma {state.sigma:g}, update factor {info['update_factor']:g}); theta is kept as "
                                  f"after generation {state.generation}")
        self.state = new_state
        center_return = float(returns[popsize])
        if math.isfinite(center_return) and center_return > self.history.best_center:
            self.history.best_center, self.history.best_theta = center_return, state.theta
        return self._record(fitness, returns[:popsize], center_return, info, int(results.steps.sum()),
                            time.perf_counter() - started)

    def _evaluate(self, generation: Generation):
        """The generation's episodes, under the live progress line; retried failures are reported."""
        after = self.run.generations - generation.number - 1
        shown = (self.display.generation(generation.number + 1, len(generation.tasks), after)
                 if self.display is not None else contextlib.nullcontext(None))
        with shown as progress:
            results = self.evaluator.evaluate(generation, progress=progress)
        for message in results.warnings:
            self.log(f"warning: {message}")
        return results

    def _record(self, fitness: np.ndarray, returns: np.ndarray, center_return: float, info: dict, steps: int,
                seconds: float) -> dict:
        """Append the generation's metrics row, rewrite metrics.csv, tell the reporters."""
        history, after, finite = self.history, self.state, np.isfinite(fitness)
        history.total_steps += steps
        history.total_seconds += seconds
        fitness, returns = fitness[finite], returns[finite]

        def stat(values: np.ndarray, reduce) -> float:  # finite values only; NaN if there are none
            return float(reduce(values)) if values.size else math.nan

        penalised = after.theta[self.policy.penalised]
        row = dict(generation=after.generation, fitness_mean=stat(fitness, np.mean), fitness_max=stat(fitness, np.max),
                   fitness_min=stat(fitness, np.min), fitness_std=stat(fitness, np.std),
                   return_mean=stat(returns, np.mean), center_return=center_return, sigma=after.sigma, lr=after.lr,
                   update_factor=info["update_factor"], skipped=int(info["skipped"]),
                   nonfinite=int((~finite).sum()), env_steps=steps, total_env_steps=history.total_steps,
                   seconds=round(seconds, 3), total_seconds=round(history.total_seconds, 3),
                   parameters_name=self.policy.penalised_name, parameters_sum=float(penalised.sum()),
                   parameters_abs_sum=float(np.abs(penalised).sum()))
        history.metrics.append(row)
        if after.generation % self.run.print_every == 0:
            history.fitness_log.append(row["fitness_mean"])
        self.folder.write_metrics(history.metrics)
        for reporter in self.reporters:
            reporter.generation(row)
        return row

    def save(self) -> None:
        """The run's files, what the reporters save, and last the checkpoint: a save cut short
        leaves the previous checkpoint to resume from."""
        self.folder.save_generation(self.policy, self.state, self.history, self.label, self.es.popsize)
        for reporter in self.reporters:
            reporter.saved(self.folder, self.history.metrics)
        self.save_checkpoint()

    def save_checkpoint(self) -> None:
        self.folder.save_checkpoint(Checkpoint.of(self.state, self.history))

    def restore(self, checkpoint: Checkpoint) -> None:
        """Continue from ``checkpoint``; metrics rows after it are dropped."""
        if checkpoint.theta.shape != (self.policy.num_params,):
            raise ValueError(f"{self.folder.path / 'checkpoint.npz'} holds {checkpoint.theta.size} parameters; "
                             f"this run needs {self.policy.num_params}")
        self.state = checkpoint.state()
        self.history = checkpoint.history(self.folder.read_metrics(checkpoint.generation))

    def _stop(self, error: Exception) -> Status:
        """Report what stopped the run, and checkpoint it if that still works."""
        self.failure = error
        self.log(f"error: {error}")
        if not isinstance(error, SaveError):  # a failed save would most likely fail again
            try:
                self.save_checkpoint()
            except SaveError as save_error:
                self.log(f"error: {save_error}")
        return Status.FAILED

    def close(self) -> None:
        self.evaluator.close()
        self.noise.close()
