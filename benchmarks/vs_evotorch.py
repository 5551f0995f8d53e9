#!/usr/bin/env python
"""Environment steps to solve CartPole-v1, this tool against EvoTorch 0.6.1, judged by the same code.

    python benchmarks/vs_evotorch.py --strategies snes,pgpe --settings matched,matched_from_zeros,defaults --seeds 10

The speed side by side is ``benchmarks/vs_evotorch_speed.py``; this script counts steps, which no load moves
(its record is not timed).

**The runs.** Each (strategy, settings) row runs ``--seeds`` seeds (1, 2, ...) of each tool, every run seeded:
this tool's runs are a function of their seed; EvoTorch's are seeded through torch (its sampling), numpy and
random, and its environment's reset stream is seeded once from numpy's (``peers/evotorch_train.SeededEnv``:
GymNE resets without a seed). Both tools evolve the same network, obs -> 128 -> 64 -> actions, no biases,
tanh, each in this process (this tool with ``--threads 1``, GymNE without Ray actors).

**The judge.** After every generation the centre of either tool (EvoTorch's ``status["center"]``, whose
layout is this tool's: ``tests/test_vs_evotorch.py``) runs ``--test_episodes`` episodes through this tool's
evaluation (``envs.evaluation.evaluate``, the rollout of training and of ``evaluate_static.py``), on held-out
seeds: ``base, base + 1, ...`` with ``base`` drawn from the run's seed in [2**31, 2**32 - episodes), a range no
training episode's seed comes from (this tool's are below 2**31 - 1; EvoTorch's environment is seeded once
below 2**31 and then continues its own stream). The same seeds judge both tools' runs of a seed. With
observation normalisation the centre is judged with its tool's statistics at that moment (EvoTorch's
``get_observation_stats()``, which normalise as this tool's: (x - mean) / max(std, 0.1), no clip). A run is
*solved* at the first generation whose centre's mean return over those episodes reaches ``--target``
(CartPole-v1's 475); the judge's episodes are not counted.

**What is counted.** The environment steps of the members' training episodes, up to and including the
generation that solved: EvoTorch's ``interaction_count``, this tool's members' episodes. This tool's loop also
runs its centre once a generation (the original's ``center_return``, a log that no update uses); those
steps are left out, as EvoTorch runs no such episode: one rule for both. (They would add 1 / (popsize + 1)
to this tool's counts.)

**Unsolved runs.** A run stops once its steps reach ``--budget``; a run not solved by then counts as the
budget: a censored value (it needed at least that many), so the statistics rank it behind every solved run,
on both sides alike.

**The statistics** (``report/stats.py``, rliable): per row and tool the interquartile mean of the steps to
solve with its 95 % stratified bootstrap interval, and the probability that a run of this tool needs fewer
steps than a run of EvoTorch, P(this tool < EvoTorch) (ties count a half), with its interval.

**The rows.** ``matched``: the same settings on both sides, EvoTorch's CartPole settings where it documents
them (σ from EvoTorch's radius 2.25, observation normalisation on every episode, population 64, each
strategy's learning rates, the same initial centre: this tool's initialisation for the seed, no L2 penalty in
this tool's fitness). ``matched_from_zeros``: the same, both starting from zeros, as EvoTorch's example does
(its own default centre is U(±1e-5)). ``defaults``: each tool as its documentation sets it up: this tool's
``train_static.py --strategy S`` defaults; EvoTorch's CartPole example (PGPE,
examples/notebooks/Functional_API/problem.ipynb) and its documented SNES for networks
(docs/user_guide/supervised_ne.md), both with the example's observation normalisation. The record holds the
settings table, each run's steps, and the results table (docs/strategies.md renders both). Needs: pip install
-r requirements-bench.txt
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from peers import evotorch_train
from peers.evotorch_train import EvoTorchSettings
from record import Record, add_results_flag, documented_parser

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from envs import ProblemSpec
from envs.evaluation import evaluate
from es.loop import Trainer
from es.runfolder import RunFolder
from es.settings import ESSettings, RunSettings
from es.strategies.pgpe import default_max_speed
from es.strategies.snes import default_sigma_lr
from policies import PolicySettings

INSTALL_HINT = "pip install -r requirements-bench.txt"
STRATEGIES = ("snes", "pgpe")
SETTINGS = ("matched", "matched_from_zeros", "defaults")
HELD_OUT = (2**31, 2**32)  # the judge's seeds; this tool's training seeds are below 2**31 - 1
HELD_OUT_STREAM = 5  # the judge's seeds are drawn from [run seed, HELD_OUT_STREAM]
EVOTORCH_RADIUS = 2.25  # radius_init of EvoTorch's CartPole example and of its networks' examples
MATCHED_POPSIZE = 64


# --- the rows: each tool's settings ---------------------------------------------------------------


@dataclass(frozen=True)
class Ours:
    es: ESSettings
    obs_norm: bool
    centre: str = "this tool"  # where the search starts: this tool's initialisation for the seed, or "zeros"


@dataclass(frozen=True)
class Row:
    strategy: str
    settings: str
    ours: Ours
    theirs: EvoTorchSettings


def rows(strategies: list[str], settings: list[str], dim: int) -> list[Row]:
    """The rows asked for, for a network of ``dim`` parameters."""
    sigma = EVOTORCH_RADIUS / math.sqrt(dim)  # EvoTorch's radius_init, as a standard deviation
    # EvoTorch's CartPole example (PGPE): max_speed 0.15, center_learning_rate 0.75 * it, radius 15 * it
    pgpe = dict(center_lr=0.1125, sigma_lr=0.1, max_speed=0.15, max_sigma_change=0.2)
    made = []
    for strategy in strategies:
        for name in settings:
            if name.startswith("matched"):
                common = dict(popsize=MATCHED_POPSIZE, sigma=sigma, obs_norm_prob=1.0, fitness_l2=0.0)
                ours = (ESSettings(strategy="pgpe", pgpe_lr=pgpe["center_lr"], clipup_max_speed=pgpe["max_speed"],
                                   pgpe_sigma_lr=pgpe["sigma_lr"], pgpe_max_sigma_change=pgpe["max_sigma_change"],
                                   **common) if strategy == "pgpe" else ESSettings(strategy="snes", **common))
                centre = "zeros" if name == "matched_from_zeros" else "this tool"
                theirs = EvoTorchSettings(strategy, MATCHED_POPSIZE, sigma=sigma, obs_norm=True, centre=centre,
                                          **(pgpe if strategy == "pgpe" else {}))
                made.append(Row(strategy, name, Ours(ours, True, centre), theirs))
            else:
                theirs = (EvoTorchSettings("pgpe", 100, radius=EVOTORCH_RADIUS, obs_norm=True, centre="zeros", **pgpe)
                          if strategy == "pgpe" else
                          EvoTorchSettings("snes", 50, radius=EVOTORCH_RADIUS, obs_norm=True))
                made.append(Row(strategy, name, Ours(ESSettings(strategy=strategy), False), theirs))
    return made


def settings_table(row: Row, dim: int) -> list[list]:
    """Two rows of the settings table: what each tool ran with, defaults resolved to numbers."""
    es, theirs = row.ours.es, row.theirs
    if row.strategy == "pgpe":
        speed = es.clipup_max_speed or default_max_speed(es.sigma, dim)
        ours_rates = (f"centre {es.pgpe_lr or speed / 2:.4g} (ClipUp, max speed {speed:.3g}, momentum "
                      f"{es.clipup_momentum:g}); σ {es.pgpe_sigma_lr:g}, change ≤ {es.pgpe_max_sigma_change:g}")
        their_rates = (f"centre {theirs.center_lr:.4g} (ClipUp, max speed {theirs.max_speed:.3g}, momentum 0.9); "
                       f"σ {theirs.sigma_lr:g}, change ≤ {theirs.max_sigma_change:g}")
    else:
        ours_rates = f"centre {es.snes_lr:g}; σ {es.snes_sigma_lr or default_sigma_lr(dim):.4g}"
        their_rates = f"centre {theirs.center_lr or 1:g}; σ {0.2 * (3 + math.log(dim)) / math.sqrt(dim):.4g}"
    their_sigma = theirs.sigma if theirs.sigma is not None else theirs.radius / math.sqrt(dim)
    ours_norm = f"yes, every episode{'' if es.obs_norm_prob == 1 else f' × {es.obs_norm_prob:g}'}" \
        if row.ours.obs_norm else "no"
    centre = {"this tool": "this tool's initialisation", "zeros": "zeros", "evotorch": "EvoTorch's, U(±1e-5)"}
    return [[row.strategy, row.settings, "this tool", es.popsize, f"{es.sigma:.4g}", ours_norm, ours_rates,
             f"{es.fitness_l2:g}", centre[row.ours.centre]],
            [row.strategy, row.settings, "EvoTorch", theirs.popsize, f"{their_sigma:.4g}",
             "yes, every episode" if theirs.obs_norm else "no", their_rates, "–", centre[theirs.centre]]]


# --- the judge ------------------------------------------------------------------------------------


class Judge:
    """This tool's evaluation of a centre, on held-out seeds: the one judge of both tools' runs."""

    def __init__(self, environment: str, obs_norm: bool, episodes: int, target: float):
        self.problem = ProblemSpec((environment,), PolicySettings(obs_norm=obs_norm)).build()
        self.episodes, self.target = episodes, target

    def first_seed(self, run_seed: int) -> int:
        low, high = HELD_OUT
        return int(np.random.default_rng([run_seed, HELD_OUT_STREAM]).integers(low, high - self.episodes))

    def solved(self, centre: np.ndarray, statistics: tuple[np.ndarray, np.ndarray] | None, run_seed: int) -> bool:
        """Whether ``centre``, normalising with ``statistics`` (None: none gathered yet, the identity), reaches
        the target on the run's held-out seeds."""
        size = self.problem.policy.normalised_inputs
        if size:
            self.problem.policy.observe(statistics if statistics is not None else (np.zeros(size), np.ones(size)))
        [report] = evaluate(self.problem, np.asarray(centre, dtype=np.float32), self.episodes,
                            self.first_seed(run_seed))
        return report.mean >= self.target

    def close(self) -> None:
        self.problem.close()


def initial_centre(judge: Judge, seed: int) -> np.ndarray:
    """This tool's generation-0 centre for ``seed`` (es.loop.Trainer draws it from [seed, 1])."""
    return judge.problem.policy.initial_params(np.random.default_rng([seed, 1]))


# --- one run of each tool -------------------------------------------------------------------------


class MemberSteps:
    """This tool's evaluator, counting the steps of the members' episodes (not the centre's)."""

    def __init__(self, inner, popsize: int):
        self.inner, self.popsize, self.steps = inner, popsize, 0
        self.workers = inner.workers

    def evaluate(self, generation, progress=None):
        results = self.inner.evaluate(generation, progress)
        self.steps += int(results.steps[generation.tasks["member"] < self.popsize].sum())
        return results

    def close(self) -> None:
        self.inner.close()


def run_ours(row: Row, args: argparse.Namespace, seed: int, judge: Judge) -> int | None:
    """Members' steps when this tool's centre is first judged solved; None if not within the budget."""
    spec = ProblemSpec((args.environment,), PolicySettings(obs_norm=row.ours.obs_norm))
    with tempfile.TemporaryDirectory() as folder:
        trainer = Trainer.start(row.ours.es, RunSettings(generations=10**9, threads=1, seed=seed), spec.build(),
                                spec.build, spec.env_ids, RunFolder(Path(folder)), args.environment,
                                log=lambda line: None)
        trainer.evaluator = counter = MemberSteps(trainer.evaluator, row.ours.es.popsize)
        if row.ours.centre == "zeros":
            trainer.state = trainer.strategy.initial_state(np.zeros_like(trainer.state.theta))
        try:
            while counter.steps < args.budget:
                trainer.generation()
                statistics = trainer.observations.published() if trainer.observations is not None else None
                if judge.solved(trainer.state.theta, statistics, seed):
                    return counter.steps if counter.steps <= args.budget else None
        finally:
            trainer.close()
    return None


def run_evotorch(row: Row, args: argparse.Namespace, seed: int, judge: Judge) -> int | None:
    """EvoTorch's steps when its centre is first judged solved; None if not within the budget."""
    import torch

    evotorch_train.seed_everything(seed)
    torch.set_num_threads(1)
    problem = evotorch_train.problem(args.environment, row.theirs.obs_norm)
    centre = initial_centre(judge, seed) if row.theirs.centre == "this tool" else None
    if centre is not None and centre.size != problem.solution_length:
        raise SystemExit(f"the networks differ: {centre.size} parameters here, {problem.solution_length} in EvoTorch")
    searcher = evotorch_train.searcher(problem, row.theirs, None if centre is None else torch.from_numpy(centre))
    while problem.interaction_count < args.budget:
        searcher.step()
        statistics = None
        if row.theirs.obs_norm and problem.get_observation_stats().count > 0:
            stats = problem.get_observation_stats()
            statistics = (np.asarray(stats.mean, np.float64), np.asarray(stats.stdev, np.float64))
        centre = searcher.status["center"].cpu().numpy().astype(np.float32)
        if judge.solved(centre, statistics, seed):
            return problem.interaction_count if problem.interaction_count <= args.budget else None
    return None


# --- the comparison ---------------------------------------------------------------------------------


def censored(steps: list[int | None], budget: int) -> list[float]:
    """Steps to solve, an unsolved run counted as the budget."""
    return [float(budget if value is None else value) for value in steps]


def estimate(value: float, low: float, high: float, digits: int | None = None) -> dict:
    return {"value": value, "low": low, "high": high, **({} if digits is None else {"digits": digits})}


def compare(row: Row, args: argparse.Namespace) -> tuple[list[int | None], list[int | None]]:
    """Each seed's steps to solve, this tool's and EvoTorch's (None: not within the budget). Each tool's judge
    normalises observations where that tool's runs do; otherwise they are one and the same code."""
    judges = {obs_norm: Judge(args.environment, obs_norm, args.test_episodes, args.target)
              for obs_norm in {row.ours.obs_norm, row.theirs.obs_norm}}
    ours, theirs = [], []
    try:
        for seed in range(1, args.seeds + 1):
            ours.append(run_ours(row, args, seed, judges[row.ours.obs_norm]))
            theirs.append(run_evotorch(row, args, seed, judges[row.theirs.obs_norm]))
            print(f"{row.strategy} {row.settings} seed {seed}: this tool {show(ours[-1])}, EvoTorch {show(theirs[-1])}",
                  flush=True)
    finally:
        for judge in judges.values():
            judge.close()
    return ours, theirs


def show(steps: int | None) -> str:
    return "not solved" if steps is None else f"{steps:,}"


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    try:
        import evotorch
    except ImportError:
        print(f"vs_evotorch.py: error: needs EvoTorch, which is not installed; {INSTALL_HINT}", file=sys.stderr)
        return 2
    import logging

    from report.stats import improvements, summarise

    logging.getLogger("evotorch").setLevel(logging.WARNING)
    # the record's name is its command's: the rows asked for, where they are not the default ones
    defaults = ((args.strategies, ["snes", "pgpe"]), (args.settings, list(SETTINGS)))
    asked = [",".join(value) for value, default in defaults if value != default]
    record = Record("-".join(["vs_evotorch", args.environment, *asked]), ("evotorch", "rliable"), timed=False)
    sized = ProblemSpec((args.environment,)).build()
    dim = sized.policy.num_params
    sized.close()
    chosen = rows(args.strategies, args.settings, dim)
    settings, results = [], []
    for row in chosen:
        ours, theirs = compare(row, args)
        key = f"{row.strategy}_{row.settings}"
        for tool, steps in (("this_tool", ours), ("evotorch", theirs)):
            record.add(f"{key}_{tool}", f"{row.strategy}, {row.settings} settings: {tool}'s environment steps to "
                       f"solve {args.environment}, one value per seed (unsolved: the budget)", "steps",
                       censored(steps, args.budget))
        record.note(f"{key}_seeds", {"seeds": list(range(1, args.seeds + 1)), "this tool": ours, "EvoTorch": theirs})
        scores = {"this tool": censored(ours, args.budget), "EvoTorch": censored(theirs, args.budget)}
        summary = {s.group: s for s in summarise(scores, args.reps)}
        [fewer] = [p for p in improvements({name: [-v for v in values] for name, values in scores.items()}, args.reps)
                   if p.x == "this tool"]
        settings += settings_table(row, dim)
        results.append([row.strategy, row.settings,
                        *(estimate(summary[name].iqm, summary[name].iqm_low, summary[name].iqm_high)
                          for name in ("this tool", "EvoTorch")),
                        f"{sum(v is not None for v in ours)}/{args.seeds}",
                        f"{sum(v is not None for v in theirs)}/{args.seeds}",
                        estimate(fewer.probability, fewer.low, fewer.high, digits=2)])
        iqm = {name: f"{s.iqm:,.0f} [{s.iqm_low:,.0f}, {s.iqm_high:,.0f}]" for name, s in summary.items()}
        print(f"## {row.strategy}, {row.settings}: IQM steps to solve, this tool {iqm['this tool']}, EvoTorch "
              f"{iqm['EvoTorch']}; P(this tool needs fewer) {fewer.probability:.2f} [{fewer.low:.2f}, "
              f"{fewer.high:.2f}]", flush=True)
    record.table("settings", ["strategy", "settings", "tool", "population", "σ", "observation normalisation",
                              "learning rates", "fitness L2", "initial centre"], settings)
    record.table("results", ["strategy", "settings", "this tool: IQM steps [95 % CI]",
                             "EvoTorch: IQM steps [95 % CI]", "this tool solved", "EvoTorch solved",
                             "P(this tool needs fewer) [95 % CI]"], results)
    record.note("protocol", {"budget": args.budget, "target": args.target, "test_episodes": args.test_episodes,
                             "seeds": args.seeds, "reps": args.reps, "evotorch": evotorch.__version__})
    record.write(args.results)
    return 0


def parse(argv: list[str] | None) -> argparse.Namespace:
    parser = documented_parser(__doc__)
    parser.add_argument("--environment", default="CartPole-v1")
    parser.add_argument("--strategies", default="snes,pgpe", help="comma-separated, of " + ", ".join(STRATEGIES))
    parser.add_argument("--settings", default=",".join(SETTINGS), help="comma-separated, of " + ", ".join(SETTINGS))
    parser.add_argument("--seeds", type=int, default=10, help="runs of each tool per row: seeds 1 .. N")
    parser.add_argument("--budget", type=int, default=500_000,
                        help="environment steps after which a run stops; unsolved, it counts as this many")
    parser.add_argument("--target", type=float, default=475.0, help="the mean held-out return that solves")
    parser.add_argument("--test_episodes", type=int, default=10, help="the judge's held-out episodes")
    parser.add_argument("--reps", type=int, default=2000, help="bootstrap replications")
    add_results_flag(parser)
    args = parser.parse_args(argv)
    for flag, chosen, valid in (("--strategies", args.strategies, STRATEGIES), ("--settings", args.settings, SETTINGS)):
        unknown = [name for name in chosen.split(",") if name not in valid]
        if unknown:
            parser.error(f"{flag}: unknown {', '.join(unknown)}; choose from {', '.join(valid)}")
    args.strategies, args.settings = args.strategies.split(","), args.settings.split(",")
    if args.seeds < 1 or args.budget < 1 or args.test_episodes < 1:
        parser.error("--seeds, --budget and --test_episodes must be at least 1")
    return args


if __name__ == "__main__":
    sys.exit(main())
