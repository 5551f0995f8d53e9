"""The generation loop of a training run: ask -> tasks -> evaluate -> fitness -> tell -> record.

All randomness of generation g comes from ``generation_rng(seed, g)`` (the members, their episode
seeds, the centre's), from ``stream_rng(seed, RECORD_STREAM, g)`` (which mirrored pairs, or members, add their
observations to the ``--obs_norm`` statistics) and ``stream_rng(seed, EVAL_STREAM, g)`` (the seeds of
the centre's ``--eval_every`` episodes), and the noise table and theta_0 from the seed alone, so a
run is a pure function of its settings: the same seed gives the same theta with any backend and
number of workers, and a resumed run continues exactly where it stopped.

Every generation the unperturbed centre runs one episode per member-episode on seeds of its own
(the original's, and the row's ``center_return`` and ``center_rank``: pytorch-es's "rank of the
unperturbed model", 1 + the members that returned more; 1 of N + 1 means no perturbation
improved on it). With ``--eval_every G`` it also runs ``--eval_episodes K`` episodes every G
generations, as extra tasks of the same parallel generation, on seeds drawn from
[2^31, 2^32), a range training seeds (< 2^31 - 1) never come from; their mean then picks best. The
loop knows arrays, workers and files; the policy only through its protocol
(``num_params``, ``initial_params``, ``penalised``, ``export``, ``file_name``), the environments
not at all. What the user sees goes through the injected ``log`` and display, and the caller is handed each
generation's record (``GenerationRecord``: its metrics row, and whether the run's files were saved after it)
through one callback, ``on_generation``: the training script prints it, draws it and sends it to the loggers,
which it makes and closes itself (``cli.train``).

The strategy is injected (``Trainer(..., strategy=...)``; by default the one ``--strategy`` names in
``es.strategies.STRATEGIES``) and known only through its ask/tell (``es.strategy.Strategy``): its
``Population`` says what the workers rebuild, and members that are mirrored pairs share their episode
seeds (common random numbers); otherwise each member has seeds of its own.
"""

from __future__ import annotations

import contextlib
import enum
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace

import numpy as np

from es.backends import EvaluationError, Evaluator, Generation, WorkerStartError, make_evaluator
from es.interrupts import Interrupts
from es.noise import NoiseTable, default_size
from es.observations import RunningStat
from es.runfolder import Checkpoint, History, RunFolder, SaveError
from es.settings import ESSettings, RunSettings
from es.shaping import penalised_fitness
from es.strategies import make_strategy
from es.strategy import Population, Strategy
from es.worker import TASK_DTYPE, make_tasks
from settings import EPISODE_SEED_RANGE, SEED_RANGE

SEED_LIMIT = SEED_RANGE[1]  # training episodes' seeds are below it: 2**31 - 1
EVAL_SEEDS = (SEED_RANGE[1] + 1, EPISODE_SEED_RANGE[1] + 1)  # the centre evaluation's: [2**31, 2**32)
RECORD_STREAM, EVAL_STREAM = 3, 4


class NonFiniteUpdate(RuntimeError):
    """A step that would make theta NaN or infinite (an lr too large, a sigma too small)."""


class Status(enum.Enum):
    DONE = "done"
    INTERRUPTED = "interrupted"  # by Ctrl-C or SIGTERM, after a save
    FAILED = "failed"  # an episode failed twice, a worker could not start, or a file could not be written


GENERATION_STREAM = 2  # the perturbations and episode seeds; the options' streams are others


def generation_rng(seed: int, generation: int) -> np.random.Generator:
    return stream_rng(seed, GENERATION_STREAM, generation)


def stream_rng(seed: int, stream: int, generation: int) -> np.random.Generator:
    """A stream of its own per option, so that an option never moves the draws of the others."""
    return np.random.default_rng([seed, stream, generation])


@dataclass(frozen=True)
class CenterReport:
    """What the generation's tasks said about the unperturbed centre."""

    center_return: float  # on its own training-like seeds, as the original
    center_rank: int  # 1 + the members whose return beat it
    center_eval_mean: float = math.nan  # --eval_every generations: over the K evaluation episodes
    center_eval_std: float = math.nan


@dataclass(frozen=True)
class GenerationRecord:
    """What the loop hands its caller after each generation."""

    row: dict  # its metrics row, as metrics.csv now ends
    rows: list[dict]  # every metrics row so far, this one last (the loop's own list: read it, never change it)
    saved: bool  # the run's files were saved after it (every --print_every generations, the last, at a stop)


class Trainer:
    def __init__(self, es: ESSettings, run: RunSettings, policy, noise: NoiseTable, evaluator: Evaluator,
                 n_envs: int, folder: RunFolder, label: str, log: Callable[[str], None] = print,
                 display=None, on_generation: Callable[[GenerationRecord], None] | None = None,
                 strategy: Strategy | None = None):
        self.es, self.run, self.policy, self.noise, self.evaluator = es, run, policy, noise, evaluator
        self.n_envs, self.folder, self.label, self.log = n_envs, folder, label, log
        self.display, self.on_generation = display, on_generation
        self.strategy = strategy if strategy is not None else make_strategy(es, policy.num_params)
        self.state = self.strategy.initial_state(policy.initial_params(np.random.default_rng([run.seed, 1])))
        self.history = History()
        self.failure: Exception | None = None  # what stopped the run, if something did
        # --obs_norm: the statistics the next generation's episodes normalise with
        self.observations = RunningStat.empty(policy.normalised_inputs) if policy.normalised_inputs else None

    @classmethod
    def start(cls, es: ESSettings, run: RunSettings, problem, build_problem: Callable[[], object],
              env_ids: tuple[str, ...], folder: RunFolder, label: str, **options) -> Trainer:
        """Noise table and evaluator for ``problem`` (built here, reused by the serial backend)."""
        dim = problem.policy.num_params
        es = replace(es, noise_size=es.noise_size or default_size(dim))
        if es.noise_size < dim:  # noise_size, from an experiment file or config.json
            raise ValueError(f"--noise_size {es.noise_size} is smaller than the {dim} parameters; leave it out "
                             f"(the default sizes it) or give at least {dim}")
        if options.get("strategy") is None:  # made before the workers start: it may refuse the run
            options["strategy"] = make_strategy(es, dim)
        noise = NoiseTable.create(run.seed, es.noise_size, shared=not run.in_process)
        try:
            evaluator = make_evaluator(run, build_problem, noise, dim, env_ids, problem)
        except BaseException:
            noise.close()
            raise
        return cls(es, run, problem.policy, noise, evaluator, len(env_ids), folder, label, **options)

    def train(self) -> Status:
        """Generations up to ``run.generations``; saves every ``print_every``, at the end and when interrupted;
        each generation's record handed to ``on_generation``."""
        with Interrupts() as interrupts:
            try:
                while self.state.generation < self.run.generations:
                    row = self._step()
                    with interrupts.held():  # the metrics row and the save it may take agree, even at a stop
                        self.folder.write_metrics(self.history.metrics, self.policy.metrics_columns)
                        done = self.state.generation
                        saved = done % self.run.print_every == 0 or done == self.run.generations or interrupts.requested
                        if saved:
                            self.save()
                        self._hand_on(row, saved)
                        if interrupts.requested and not saved:  # asked for while the record was handed on
                            self.save()
                    if interrupts.requested:
                        return Status.INTERRUPTED
            except (EvaluationError, WorkerStartError, SaveError, NonFiniteUpdate) as error:
                return self._stop(error)
        return Status.DONE

    def generation(self) -> dict:
        """One generation, top to bottom, its metrics row written and handed on (no save); the row."""
        row = self._step()
        self.folder.write_metrics(self.history.metrics, self.policy.metrics_columns)
        self._hand_on(row, False)
        return row

    def _hand_on(self, row: dict, saved: bool) -> None:
        if self.on_generation is not None:
            self.on_generation(GenerationRecord(row, self.history.metrics, saved))

    def _step(self) -> dict:
        """One generation's episodes and update; its metrics row, kept in the history but not yet written."""
        started, state, popsize = time.perf_counter(), self.state, self.es.popsize
        rng = generation_rng(self.run.seed, state.generation)
        population = self.strategy.ask(state, rng, self.noise)
        repeat = 2 if population.mirrored else 1  # a mirrored pair shares its episode seeds
        group_seeds = rng.integers(0, SEED_LIMIT, size=(popsize // repeat, self.es.episodes))
        center_seeds = rng.integers(0, SEED_LIMIT, size=(1, self.es.episodes))
        tasks = make_tasks(np.arange(popsize + 1), np.append(population.indices, -1), np.append(population.signs, 0),
                           np.concatenate([np.repeat(group_seeds, repeat, axis=0), center_seeds]), self.n_envs,
                           self._recorded(state.generation, group_seeds.shape, repeat),
                           cap := self.history.episode_cap)
        training_tasks = len(tasks)
        tasks = np.concatenate([tasks, self._evaluation_tasks(state.generation)])
        results = self._evaluate(self._published(state, population, tasks))
        returns = results.returns[:training_tasks].reshape(popsize + 1, -1).mean(axis=1)  # the centre is last
        penalties = results.penalties[:training_tasks].reshape(popsize + 1, -1)[:, 0]  # equal on a member's tasks
        fitness = penalised_fitness(returns[:popsize], penalties[:popsize], self.es.fitness_l2)
        new_state, info = self.strategy.tell(state, self.noise, population, fitness)
        if not np.isfinite(new_state.theta).all():  # stop where it appears, keeping the last finite theta
            raise NonFiniteUpdate(f"generation {state.generation + 1}: the update is not finite (lr {state.lr:g}, "
                                  f"sigma {state.sigma:g}, update factor {info['update_factor']:g}); theta is kept as "
                                  f"after generation {state.generation}")
        self.state = new_state
        center = self._center(state, returns, results.returns[training_tasks:])
        if self.observations is not None:
            self.observations = self.observations.merged(results.observations)
        if self.es.variable_ep_len:  # pytorch-es: twice the mean length of the perturbed episodes
            member_tasks = training_tasks - training_tasks // (popsize + 1)
            self.history.episode_cap = max(1, int(2 * results.steps[:member_tasks].mean()))
        return self._record(fitness, returns[:popsize], center, info, int(results.steps.sum()), cap,
                            time.perf_counter() - started)

    def _published(self, state, population: Population, tasks: np.ndarray) -> Generation:
        """What the workers receive once this generation: theta, sigma, the observation statistics,
        and the strategy's per-parameter sigma or members' vectors."""
        statistics = self.observations.published() if self.observations is not None else None
        return Generation(state.generation, state.theta, state.sigma, tasks, statistics, scale=population.scale,
                          rows=population.rows)

    def _recorded(self, generation: int, shape: tuple[int, int], repeat: int) -> np.ndarray | None:
        """--obs_norm: which episodes of each mirrored pair (both members alike; ``repeat`` 2), or of
        each member (``repeat`` 1), add their observations."""
        if self.observations is None:
            return None
        draws = stream_rng(self.run.seed, RECORD_STREAM, generation).random(shape) < self.es.obs_norm_prob
        return np.concatenate([np.repeat(draws, repeat, axis=0), np.zeros((1, shape[1]), dtype=bool)])

    def _evaluation_tasks(self, generation: int) -> np.ndarray:
        """--eval_every generations: the centre on eval_episodes seeds of its own, on every environment."""
        if not self.es.evaluates_centre(generation):
            return np.zeros(0, dtype=TASK_DTYPE)
        seeds = stream_rng(self.run.seed, EVAL_STREAM, generation).integers(*EVAL_SEEDS,
                                                                            size=(1, self.es.eval_episodes))
        return make_tasks(np.array([self.es.popsize]), np.array([-1]), np.array([0]), seeds, self.n_envs)

    def _center(self, state, returns: np.ndarray, evaluation: np.ndarray) -> CenterReport:
        """The centre's row entries; best/best_* follow its return, or its evaluation mean with --eval_every."""
        popsize = self.es.popsize
        center_return = float(returns[popsize])
        report = CenterReport(center_return, 1 + int((returns[:popsize] > center_return).sum()))
        if evaluation.size:
            per_seed = evaluation.reshape(self.n_envs, -1).mean(axis=0)  # each seed: the mean over the envs
            report = replace(report, center_eval_mean=float(per_seed.mean()), center_eval_std=float(per_seed.std()))
        score = report.center_eval_mean if self.es.eval_every is not None else center_return
        if math.isfinite(score) and score > self.history.best_center:
            self.history.best_center, self.history.best_theta = score, state.theta
            self.history.best_observations = self.observations  # what that centre was evaluated with
        return report

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

    def _record(self, fitness: np.ndarray, returns: np.ndarray, center: CenterReport, info: dict, steps: int,
                episode_cap: int, seconds: float) -> dict:
        """Append the generation's metrics row to the history; the row."""
        history, after, finite = self.history, self.state, np.isfinite(fitness)
        history.total_steps += steps
        history.total_seconds += seconds
        fitness, returns = fitness[finite], returns[finite]

        def stat(values: np.ndarray, reduce) -> float:  # finite values only; NaN if there are none
            return float(reduce(values)) if values.size else math.nan

        penalised = after.theta[self.policy.penalised]
        row = dict(generation=after.generation, fitness_mean=stat(fitness, np.mean), fitness_max=stat(fitness, np.max),
                   fitness_min=stat(fitness, np.min), fitness_std=stat(fitness, np.std),
                   return_mean=stat(returns, np.mean), **asdict(center), sigma=after.sigma, lr=after.lr,
                   update_factor=info["update_factor"], skipped=int(info["skipped"]),
                   nonfinite=int((~finite).sum()), env_steps=steps, total_env_steps=history.total_steps,
                   seconds=round(seconds, 3), total_seconds=round(history.total_seconds, 3),
                   parameters_name=self.policy.penalised_name, parameters_sum=float(penalised.sum()),
                   parameters_abs_sum=float(np.abs(penalised).sum()), episode_cap=episode_cap,
                   population=self.es.popsize, **self.policy.evolved_values(after.theta))
        history.metrics.append(row)
        if after.generation % self.run.print_every == 0:
            history.fitness_log.append(row["fitness_mean"])
        return row

    def save(self) -> None:
        """The run's files, and last the checkpoint: a save cut short leaves the previous checkpoint to resume
        from."""
        self.folder.save_generation(self.policy, self.state, self.history, self.label, self.es.popsize,
                                    self.observations)
        self.save_checkpoint()

    def save_checkpoint(self) -> None:
        self.folder.save_checkpoint(Checkpoint.of(self.state, self.history, self.observations))

    def restore(self, checkpoint: Checkpoint) -> None:
        """Continue from ``checkpoint``; metrics rows after it are dropped."""
        if checkpoint.theta.shape != (self.policy.num_params,):
            raise ValueError(f"{self.folder.path / 'checkpoint.npz'} holds {checkpoint.theta.size} parameters; "
                             f"this run needs {self.policy.num_params}")
        self.state = self._checked_strategy_state(checkpoint.state())
        self.history = checkpoint.history(self.folder.read_metrics(checkpoint.generation))
        if self.observations is not None:
            self.observations = RunningStat.from_arrays(checkpoint.observations) or self.observations

    def _checked_strategy_state(self, state):
        """The checkpoint's strategy arrays must be those this run's strategy keeps (names and shapes)."""
        expected = {name: np.shape(array) for name, array in self.state.strategy.items()}
        found = {name: np.shape(array) for name, array in state.strategy.items()}
        if found != expected:
            raise ValueError(f"{self.folder.path / 'checkpoint.npz'} holds the state of another strategy "
                             f"({', '.join(sorted(found)) or 'none'}) than this run's --strategy {self.es.strategy} "
                             f"({', '.join(sorted(expected)) or 'none'})")
        return state

    def _stop(self, error: Exception) -> Status:
        """Keep what stopped the run (``failure``, for the caller to report), and checkpoint it if that
        still works."""
        self.failure = error
        if not isinstance(error, SaveError):  # a failed save would most likely fail again
            try:
                self.save_checkpoint()
            except SaveError as save_error:
                self.log(f"error: {save_error}")
        return Status.FAILED

    def close(self) -> None:
        self.evaluator.close()
        self.noise.close()
