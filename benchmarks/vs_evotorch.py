#!/usr/bin/env python
"""This tool against EvoTorch 0.6.1 on the same task, network and population, one strategy at a time.

    python benchmarks/vs_evotorch.py --environment CartPole-v1 --seeds 5 --popsize 16 --generations 30
    python benchmarks/vs_evotorch.py --environment HalfCheetah-v5 --seeds 3 --popsize 16 --generations 5
    python benchmarks/vs_evotorch.py --strategies openai,pgpe,snes,sep_cma_es ...
    python benchmarks/vs_evotorch.py --strategies pgpe --popsize 100 --radius 2.25 --clipup_max_speed 0.15 \
        --pgpe_lr 0.1125 --generations 50    # EvoTorch's CartPole example's PGPE settings

Both tools evolve the same network, obs -> 128 -> 64 -> actions, no biases, tanh hidden layers, the
output argmax-ed (Discrete) or clipped (Box) (policies/network.py; EvoTorch's GymNE with the same layer
string), from the same initial centre (this tool's initialisation for the seed), with the same
population, in ONE process each (this tool with --threads 1, GymNE without Ray
actors), from the same seed. Every generation each tool also runs its centre once (this tool's loop
does; for EvoTorch, ``GymNE.run`` on the centre, whose steps are added to its count) and a run is
*solved* at the first generation whose centre return reaches --target (CartPole-v1: 475). A run
stops there, or after --generations. One untimed generation of each tool comes first (imports, numba's
compilation). EvoTorch's episodes start from unseeded resets (GymNE takes no seed), so its runs are
not repeatable; this tool's are.

Measured per seed: environment steps per second (all of a run's steps over its generations' wall time,
setup excluded) and environment steps to solve. The two tools alternate within one invocation (seed 1:
this tool first, seed 2: EvoTorch first, ...) so that the machine's drift falls on both. Printed per
strategy: each seed's figures, the ratio of steps per second (this tool / EvoTorch) as median and
range over the seeds, and the median steps to solve (unsolved runs count as not solved: the median is
then "not solved" if half of them are).

The counterparts (COUNTERPARTS): this tool's ``openai`` (OpenAI-ES: mirrored sampling, centred ranks
standardised, SGD step lr / (N sigma) * sum F eps) is EvoTorch's PGPE with sigma frozen
(stdev_learning_rate 0), centred ranking and plain gradient ascent at center_learning_rate
lr / (sigma^2 * std of the centred ranks): the same first step; ``pgpe`` is PGPE with ClipUp, given the
same maximum speed and step as this tool (--clipup_max_speed, --pgpe_lr; by default this tool's defaults
for the run's parameter count) and this tool's sigma learning rate and largest sigma change; ``snes``
SNES, ``cma_es`` / ``sep_cma_es`` CMA-ES full / separable, each with sigma and population as given
(--radius gives sigma as EvoTorch's radius_init does: sigma = radius / sqrt(parameters)).
A strategy this tool does not have (``--strategy`` of the training scripts) is reported as such.

Targets (issue 22): per environment step every strategy >= 1.5x its EvoTorch counterpart; on
CartPole-v1 this tool's PGPE and SNES need no more environment steps to solve than EvoTorch's,
median over 5 seeds. Each run writes its record to benchmarks/results/ (benchmarks/record.py): per
strategy, each seed's ratio of steps per second and both tools' steps to solve. Needs: pip install -r
requirements-bench.txt
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from record import Record, add_results_flag

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from envs import ProblemSpec
from es.loop import Trainer
from es.runfolder import RunFolder
from es.settings import ESSettings, RunSettings
from es.strategies.pgpe import default_max_speed
from policies.network import HIDDEN

INSTALL_HINT = "pip install -r requirements-bench.txt"


@dataclasses.dataclass
class Result:
    tool: str
    seed: int
    steps: int = 0
    seconds: float = 0.0
    solved_at: int | None = None  # environment steps when the centre first reached the target
    generations: int = 0
    final_centre: float = float("nan")

    @property
    def steps_per_second(self) -> float:
        return self.steps / self.seconds if self.seconds else float("nan")


def parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog="\n".join(__doc__.splitlines()[2:]))
    parser.add_argument("--environment", default="CartPole-v1")
    parser.add_argument("--strategies", default="openai", help="comma-separated, of " + ", ".join(COUNTERPARTS))
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--popsize", type=int, default=16)
    parser.add_argument("--generations", type=int, default=30, help="the most generations of a run")
    parser.add_argument("--sigma", type=float, default=ESSettings.sigma)
    parser.add_argument("--lr", type=float, default=ESSettings.lr, help="openai's learning rate")
    parser.add_argument("--radius", type=float, default=None,
                        help="the initial sigma given as the norm of the sigma vector, EvoTorch's radius_init: "
                             "sigma = radius / sqrt(parameters) for both tools (instead of --sigma)")
    parser.add_argument("--clipup_max_speed", type=float, default=None,
                        help="pgpe: ClipUp's maximum speed (default: this tool's, sigma sqrt(parameters) / 15)")
    parser.add_argument("--pgpe_lr", type=float, default=None,
                        help="pgpe: the centre's step size (default: this tool's, --clipup_max_speed / 2)")
    parser.add_argument("--target", type=float, default=None,
                        help="centre return that counts as solved (default: 475 on CartPole-v1, none elsewhere)")
    add_results_flag(parser)
    args = parser.parse_args(argv)
    unknown = [name for name in args.strategies.split(",") if name not in COUNTERPARTS]
    if unknown:
        parser.error(f"--strategies: unknown {', '.join(unknown)}; choose from {', '.join(COUNTERPARTS)}")
    if args.target is None and args.environment.startswith("CartPole"):
        args.target = 475.0
    return args


# --- this tool --------------------------------------------------------------------------------------


def our_settings(strategy: str, args: argparse.Namespace) -> ESSettings | None:
    """The ES settings of ``strategy``, or None where this version of the tool does not have it."""
    names = {field.name for field in dataclasses.fields(ESSettings)}
    values = {"popsize": args.popsize, "sigma": args.sigma}
    if "strategy" in names:
        values["strategy"] = strategy
    elif strategy != "openai":
        return None
    if strategy == "openai":
        values["lr"] = args.lr
    if strategy == "pgpe":
        values.update(pgpe_lr=args.pgpe_lr, clipup_max_speed=args.clipup_max_speed)
    try:
        return ESSettings(**values)
    except ValueError:
        return None


def our_trainer(es: ESSettings, args: argparse.Namespace, seed: int, folder: str) -> Trainer:
    spec = ProblemSpec((args.environment,))
    return Trainer.start(es, RunSettings(generations=args.generations, threads=1, seed=seed), spec.build(),
                         spec.build, spec.env_ids, RunFolder(Path(folder)), args.environment, log=lambda line: None)


def initial_centre(args: argparse.Namespace, seed: int) -> np.ndarray:
    """This tool's generation-0 centre for ``seed``: EvoTorch starts from it too. Both tools lay the
    network's weights out as torch does, (out, in) per layer, in layer order, so it is the same network."""
    with tempfile.TemporaryDirectory() as folder:
        trainer = our_trainer(ESSettings(popsize=args.popsize), args, seed, folder)
        try:
            return trainer.state.theta.copy()
        finally:
            trainer.close()


def run_ours(es: ESSettings, args: argparse.Namespace, seed: int) -> Result:
    """This tool's loop in this process (--threads 1), generation by generation, until solved."""
    result = Result("this tool", seed)
    with tempfile.TemporaryDirectory() as folder:
        trainer = our_trainer(es, args, seed, folder)
        try:
            for _ in range(args.generations):
                started = time.perf_counter()
                row = trainer.generation()
                result.seconds += time.perf_counter() - started
                result.steps += int(row["env_steps"])
                result.generations += 1
                result.final_centre = float(row["center_return"])
                if args.target is not None and result.final_centre >= args.target:
                    result.solved_at = result.steps
                    break
        finally:
            trainer.close()
    return result


# --- EvoTorch ---------------------------------------------------------------------------------------


def centred_rank_std(popsize: int) -> float:
    """The standard deviation of centred ranks (k / (N - 1) - 0.5): what standardising divides them by."""
    ranks = np.arange(popsize) / (popsize - 1) - 0.5
    return float(ranks.std())


def openai_counterpart(problem, args, centre):
    from evotorch.algorithms import PGPE

    rate = args.lr / (args.sigma ** 2 * centred_rank_std(args.popsize))
    return PGPE(problem, popsize=args.popsize, center_learning_rate=rate, stdev_learning_rate=0.0,
                stdev_init=args.sigma, optimizer=None, ranking_method="centered", symmetric=True,
                center_init=centre)


def pgpe_counterpart(problem, args, centre):
    from evotorch.algorithms import PGPE

    # ClipUp (Toklu et al. 2020) with the same step size and maximum speed as this tool's run; sigma's
    # learning rate and largest change are this tool's defaults, which are EvoTorch's example values
    es = ESSettings(strategy="pgpe")
    return PGPE(problem, popsize=args.popsize, center_learning_rate=args.pgpe_lr, stdev_learning_rate=es.pgpe_sigma_lr,
                stdev_init=args.sigma, optimizer="clipup", optimizer_config={"max_speed": args.clipup_max_speed},
                stdev_max_change=es.pgpe_max_sigma_change, ranking_method="centered", symmetric=True,
                center_init=centre)


def snes_counterpart(problem, args, centre):
    from evotorch.algorithms import SNES

    return SNES(problem, popsize=args.popsize, stdev_init=args.sigma, center_init=centre)


def cma_counterpart(separable: bool):
    def make(problem, args, centre):
        from evotorch.algorithms import CMAES

        return CMAES(problem, popsize=args.popsize, stdev_init=args.sigma, separable=separable, center_init=centre)
    return make


COUNTERPARTS = {"openai": openai_counterpart, "pgpe": pgpe_counterpart, "snes": snes_counterpart,
                "cma_es": cma_counterpart(False), "sep_cma_es": cma_counterpart(True)}


def evotorch_network() -> str:
    sizes = ("obs_length", *map(str, HIDDEN), "act_length")
    layers = [f"Linear({a}, {b}, bias=False)" for a, b in itertools.pairwise(sizes)]
    return " >> Tanh() >> ".join(layers)


def run_evotorch(strategy: str, args: argparse.Namespace, seed: int) -> Result:
    import torch
    from evotorch.neuroevolution import GymNE

    torch.manual_seed(seed)
    torch.set_num_threads(1)
    result = Result("EvoTorch", seed)
    problem = GymNE(env=args.environment, network=evotorch_network(), num_actors=None)
    centre = initial_centre(args, seed)
    if centre.size != problem.solution_length:
        raise SystemExit(f"the networks differ: {centre.size} parameters here, {problem.solution_length} in EvoTorch")
    searcher = COUNTERPARTS[strategy](problem, args, torch.from_numpy(centre))
    for _ in range(args.generations):
        started = time.perf_counter()
        before = problem.interaction_count
        searcher.step()
        centre = problem.run(searcher.status["center"], num_episodes=1)  # not counted by GymNE itself
        result.seconds += time.perf_counter() - started
        result.steps += problem.interaction_count - before + int(centre["interaction_count"])
        result.generations += 1
        result.final_centre = float(centre["cumulative_reward"])
        if args.target is not None and result.final_centre >= args.target:
            result.solved_at = result.steps
            break
    return result


# --- the comparison -----------------------------------------------------------------------------------


def median_solved(results: list[Result]) -> float:
    """Median steps to solve, an unsolved run counting as infinitely many."""
    return statistics.median([r.solved_at if r.solved_at is not None else float("inf") for r in results])


def show(value: float) -> str:
    return "not solved" if value == float("inf") else f"{value:,.0f}"


def compare(record: Record, strategy: str, args: argparse.Namespace) -> None:
    es = our_settings(strategy, args)
    if es is None:
        print(f"\n## {strategy}: this tool has no --strategy {strategy} yet; EvoTorch not run")
        return
    warm_up = argparse.Namespace(**{**vars(args), "generations": 1})  # numba's compilation, imports: untimed
    run_ours(es, warm_up, 0)
    run_evotorch(strategy, warm_up, 0)
    ours, theirs = [], []
    for number, seed in enumerate(range(1, args.seeds + 1)):
        order = (("ours", "evotorch") if number % 2 == 0 else ("evotorch", "ours"))
        for tool in order:
            (ours if tool == "ours" else theirs).append(run_ours(es, args, seed) if tool == "ours"
                                                        else run_evotorch(strategy, args, seed))
    extra = f", ClipUp max speed {args.clipup_max_speed:g}, step {args.pgpe_lr:g}" if strategy == "pgpe" else ""
    print(f"\n## {strategy} ({args.environment}, popsize {args.popsize}, sigma {args.sigma:.6g}{extra}, "
          f"at most {args.generations} generations)")
    print("| seed | tool | generations | env steps | steps/s | steps to solve | final centre return |")
    print("|---|---|---|---|---|---|---|")
    for mine, other in zip(ours, theirs):
        for result in (mine, other):
            solved = "-" if args.target is None else show(result.solved_at or float("inf"))
            print(f"| {result.seed} | {result.tool} | {result.generations} | {result.steps:,} | "
                  f"{result.steps_per_second:,.0f} | {solved} | {result.final_centre:.1f} |")
    ratios = [mine.steps_per_second / other.steps_per_second for mine, other in zip(ours, theirs)]
    record.add(f"{strategy}_steps_per_second", f"{strategy} on {args.environment}, popsize {args.popsize}: env steps "
               "per second, this tool / EvoTorch, one value per seed", "x", ratios)
    record.note(f"{strategy}_steps_to_solve", {"target": args.target, "seeds": [r.seed for r in ours],
                                               "this tool": [r.solved_at for r in ours],
                                               "EvoTorch": [r.solved_at for r in theirs]})
    print(f"steps per second, this tool / EvoTorch: median {statistics.median(ratios):.2f}x "
          f"(seeds: {min(ratios):.2f}x to {max(ratios):.2f}x; target >= 1.5x)")
    if args.target is not None:
        print(f"steps to solve (centre >= {args.target:g}), median over {args.seeds} seeds: this tool "
              f"{show(median_solved(ours))}, EvoTorch {show(median_solved(theirs))}; solved "
              f"{sum(r.solved_at is not None for r in ours)}/{args.seeds} and "
              f"{sum(r.solved_at is not None for r in theirs)}/{args.seeds}")
    print(f"final centre return, median: this tool {statistics.median(r.final_centre for r in ours):.1f}, "
          f"EvoTorch {statistics.median(r.final_centre for r in theirs):.1f}")


def resolve_defaults(args: argparse.Namespace) -> None:
    """sigma from --radius, and PGPE's maximum speed and step where not given: this tool's defaults, which
    depend on the parameter count, given to both tools as numbers."""
    parameters = initial_centre(args, 0).size
    if args.radius is not None:
        args.sigma = args.radius / parameters ** 0.5
        print(f"radius {args.radius:g} over {parameters:,} parameters: sigma {args.sigma:.6g}")
    if args.clipup_max_speed is None:
        args.clipup_max_speed = default_max_speed(args.sigma, parameters)
    if args.pgpe_lr is None:
        args.pgpe_lr = args.clipup_max_speed / 2


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    try:
        import evotorch
    except ImportError:
        print(f"vs_evotorch.py: error: needs EvoTorch, which is not installed; {INSTALL_HINT}", file=sys.stderr)
        return 2
    import logging

    logging.getLogger("evotorch").setLevel(logging.WARNING)
    print(f"EvoTorch {evotorch.__version__}; one process per tool; network {evotorch_network()}")
    record = Record(f"vs_evotorch-{args.environment}", ("evotorch", "cma", "cmaes"))
    resolve_defaults(args)
    for strategy in args.strategies.split(","):
        compare(record, strategy, args)
    record.write(args.results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
