#!/usr/bin/env python
"""Generation time of the Ray backend against the process pool, measured in one run.

    python benchmarks/ray_vs_process.py                      # AntBulletEnv-v0, popsize 32, 2 workers
    python benchmarks/ray_vs_process.py --popsize 16 --rounds 3

Both evaluators are built once (start-up is timed apart and excluded), with the same number of
workers, the same noise table and the same theta; then they evaluate the same generations of
tasks (popsize members plus the centre, as a run does) in alternating rounds, so that the machine's
drift and other load fall on both alike. The first round is a warm-up (the evaluators hand out
single episodes until they know the episode time) and is not counted. Each round also checks that
both backends return the same numbers. Target: Ray no more than 10 % slower, i.e. the
ratio of median generation times ray / process <= 1.10.

Ray's own services (raylet, GCS) stay up during the process pool's rounds too; on this 2-core
machine they cost both backends alike. Each run writes its record to benchmarks/results/
(benchmarks/record.py).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from record import Record, add_results_flag

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import envs
from envs import ProblemSpec
from es.backends import Generation, ProcessEvaluator
from es.backends.ray import RayEvaluator
from es.noise import NoiseTable, default_size
from es.worker import make_tasks

TARGET = 1.10


def generation_tasks(population: int, dim: int, noise: NoiseTable, rng: np.random.Generator) -> np.ndarray:
    """Mirrored pairs and the unperturbed centre, one episode each, as ``Run`` makes them."""
    pairs = population // 2
    indices = np.append(np.repeat(noise.sample_indices(rng, dim, pairs), 2), -1)
    signs = np.append(np.tile([1, -1], pairs), 0)
    seeds = np.repeat(rng.integers(0, 1 << 30, size=(pairs + 1, 1)), [2] * pairs + [1], axis=0)
    return make_tasks(np.arange(population + 1), indices, signs, seeds, 1)


def timed(make):
    started = time.perf_counter()
    return make(), time.perf_counter() - started


def evaluate(evaluator, generation: int, theta: np.ndarray, sigma: float, tasks: np.ndarray):
    started = time.perf_counter()
    results = evaluator.evaluate(Generation(generation, theta, sigma, tasks))
    return results, time.perf_counter() - started


def run_rounds(evaluators: dict, args, theta: np.ndarray, noise: NoiseTable) -> dict[str, list[float]]:
    """Seconds per generation of each evaluator, alternating, the warm-up round left out."""
    seconds = {name: [] for name in evaluators}
    rng = np.random.default_rng(args.seed)
    for generation in range(args.rounds + 1):
        tasks = generation_tasks(args.popsize, theta.size, noise, rng)
        order = list(evaluators) if generation % 2 == 0 else list(reversed(evaluators))
        outcomes = {name: evaluate(evaluators[name], generation, theta, args.sigma, tasks) for name in order}
        (first, _), (second, _) = outcomes.values()
        if not (np.array_equal(first.returns, second.returns) and np.array_equal(first.steps, second.steps)):
            raise SystemExit(f"round {generation}: the backends returned different results")
        steps = int(first.steps.sum())
        line = " | ".join(f"{name} {outcomes[name][1]:.2f} s" for name in evaluators)
        print(f"round {generation}{' (warm-up)' if generation == 0 else ''}: {len(tasks)} episodes, "
              f"{steps} steps | {line}", flush=True)
        if generation:
            for name in evaluators:
                seconds[name].append(outcomes[name][1])
    return seconds


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--environment", default="AntBulletEnv-v0")
    parser.add_argument("--popsize", type=int, default=32, help="members per generation (plus the centre)")
    parser.add_argument("--workers", type=int, default=2, help="worker processes / Ray actors")
    parser.add_argument("--rounds", type=int, default=5, help="measured generations per backend")
    parser.add_argument("--sigma", type=float, default=0.1)
    parser.add_argument("--seed", type=int, default=0)
    add_results_flag(parser)
    args = parser.parse_args()
    record = Record(f"ray_vs_process-{args.environment}", ("ray",))
    env_id = envs.resolve_env_id(args.environment)
    spec = ProblemSpec((env_id,))
    problem = spec.build()
    theta = problem.policy.initial_params(np.random.default_rng(args.seed))
    problem.close()
    noise = NoiseTable.create(args.seed, default_size(theta.size), shared=True)
    evaluators = {}
    try:
        evaluators["process"], process_start = timed(
            lambda: ProcessEvaluator(spec.build, noise, theta.size, spec.env_ids, args.workers))
        evaluators["ray"], ray_start = timed(
            lambda: RayEvaluator(spec.build, noise, theta.size, spec.env_ids, args.workers))
        print(f"{env_id}, popsize {args.popsize}, {args.workers} workers | start-up (excluded): "
              f"process pool {process_start:.1f} s, Ray {ray_start:.1f} s", flush=True)
        seconds = run_rounds(evaluators, args, theta, noise)
    finally:
        for evaluator in evaluators.values():
            evaluator.close()
        noise.close()
    process, ray = statistics.median(seconds["process"]), statistics.median(seconds["ray"])
    ratio = ray / process
    label = f"{env_id}, popsize {args.popsize}, {args.workers} workers"
    for name in ("process", "ray"):
        record.add(f"{name}_seconds", f"{label}: wall seconds per generation, {name}", "s", seconds[name])
    record.add("ratio", f"{label}: generation time, Ray / the process pool", "x",
               [r / p for r, p in zip(seconds["ray"], seconds["process"])])
    record.note("start_up_seconds", {"process": process_start, "ray": ray_start})
    print(f"median generation: process {process:.2f} s, ray {ray:.2f} s | ratio ray / process {ratio:.3f} "
          f"(of the sums {sum(seconds['ray']) / sum(seconds['process']):.3f}) | target <= {TARGET:.2f}: "
          f"{'met' if ratio <= TARGET else 'NOT met'}")
    record.write(args.results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
