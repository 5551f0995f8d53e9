#!/usr/bin/env python
"""Training-loop throughput against the raw speed of the environment, measured in one run.

    python benchmarks/throughput.py --environment HalfCheetah-v5 --policy static
    python benchmarks/throughput.py --environment HalfCheetah-v5 --policy hebbian --hebb_rule ABCD_lr
    python benchmarks/throughput.py --environment AntBulletEnv-v0 --policy static --scaling
    python benchmarks/throughput.py --environment ALE/Pong-v5 --network lstm
    python benchmarks/throughput.py --environment CarRacing-v3 --policy hebbian

The ratio compares, over the same episodes, the real evaluation path (the evaluator, its worker,
the recipe's wrappers, the policy, the rollout) with ``env.step`` of a plain ``gym.make``
environment replaying exactly the actions those episodes sent, from the same seeds: the same
trajectories, so it isolates what the training loop adds (a simulator's step time depends on the
state: a policy that saturates its actions makes MuJoCo slower than random actions do). The two
alternate episode by episode and are timed in CPU time of this process, so that the machine's
drift (about +-40 % here) and other load cancel out; the median over rounds is printed.
Resets are outside the raw side: on CarRacing, whose reset generates a track (about 10-20 ms) and
whose generation-0 episodes stop after some 25 steps, that alone keeps the ratio well below the
others' (``benchmarks/car_racing.py`` compares the loop with Gymnasium's class instead).
--scaling compares generations with 1 and 2 worker processes in wall time, alternating round by round.
Each run writes its record to benchmarks/results/ (benchmarks/record.py). Targets (issues 2, 3):
static MLP on HalfCheetah-v5 >= 0.85, Hebbian ABCD_lr >= 0.70 on HalfCheetah-v5 and >= 0.90 on
AntBulletEnv-v0 (--threads 1); 1 -> 2 workers on AntBulletEnv-v0 >= 1.8x (--scaling).

For image observations the preprocessing (Atari's frame skip, no-op starts, FIRE reset and frame
stack, or pytorch-es's 42 x 42 normalised frames) belongs to the environment's cost, not the
loop's: the raw side is then the environment as ``make_env`` builds it for the network (every
wrapper but the action mapping), replaying the actions the episodes chose, resets included. The
policy's own cost per step (``act``, CPU time) is printed too; issue 13's target for
``--network lstm``: <= 1 ms.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import gymnasium as gym
from record import Record, add_results_flag

import envs
from envs import ProblemSpec, make_env, quiet_output
from es.backends import Generation, ProcessEvaluator, SerialEvaluator
from es.noise import NoiseTable
from es.worker import make_tasks
from policies import NETWORKS, PolicySettings, preprocessing


def generation_tasks(population: int, dim: int, noise: NoiseTable, rng: np.random.Generator) -> np.ndarray:
    pairs = population // 2
    indices = np.repeat(noise.sample_indices(rng, dim, pairs), 2)
    signs = np.tile([1, -1], pairs)
    seeds = np.repeat(rng.integers(0, 1 << 30, size=(pairs, 1)), 2, axis=0)
    return make_tasks(np.arange(population), indices, signs, seeds, 1)


def training_rate(evaluator, theta: np.ndarray, sigma: float, tasks: np.ndarray) -> float:
    """Env steps per second per worker over one generation of the real evaluation path (wall time)."""
    started = time.perf_counter()
    results = evaluator.evaluate(Generation(0, theta, sigma, tasks))
    return results.steps.sum() / (time.perf_counter() - started) / evaluator.workers


def record_actions(evaluator: SerialEvaluator, theta: np.ndarray, sigma: float, tasks: np.ndarray,
                   preprocessed: bool):
    """The (seed, actions) of every episode of ``tasks``, as the bare environment (or, ``preprocessed``,
    the environment below the action mapping) received them; and the policy's CPU seconds per step.

    A ``step(None)`` is not an action: CarRacing's ``reset`` makes one itself to draw the first
    frame, and ``replay`` reproduces it by resetting.
    """
    problem = evaluator._worker.problem
    base = problem.envs[0].env if preprocessed else problem.envs[0].unwrapped
    episodes, step, act = [], base.step, problem.policy.act
    acting = [0.0, 0]

    def recording_step(action):
        if action is not None:
            episodes[-1][1].append(np.array(action, copy=True))
        return step(action)

    def timed_act(params, state, obs):
        started = time.process_time()
        result = act(params, state, obs)
        acting[0] += time.process_time() - started
        acting[1] += 1
        return result

    base.step, problem.policy.act = recording_step, timed_act
    try:
        for index, task in enumerate(tasks):
            episodes.append((int(task["seed"]), []))
            evaluator.evaluate(Generation(0, theta, sigma, tasks[index:index + 1]))
    finally:
        del base.step
        problem.policy.act = act
    return episodes, acting[0] / acting[1]


def replay(env: gym.Env, seed: int, actions: list[np.ndarray], with_reset: bool) -> float:
    """CPU seconds of ``env.step`` over one recorded episode (the reset too if ``with_reset``)."""
    started = time.process_time()
    env.reset(seed=seed)
    if not with_reset:
        started = time.process_time()
    for action in actions:
        env.step(action)
    return time.process_time() - started


def build(spec: ProblemSpec, workers: int, noise: NoiseTable, dim: int):
    if workers == 1:
        return SerialEvaluator(spec.build, noise, dim, spec.env_ids)
    return ProcessEvaluator(spec.build, noise, dim, spec.env_ids, workers)


def setup(args, spec: ProblemSpec, workers: int, shared: bool = False):
    """An evaluator with ``workers`` workers, its noise table (in shared memory if ``shared``, for another
    evaluator's workers too), theta and one generation of tasks, warmed up."""
    problem = spec.build()
    theta = problem.policy.initial_params(np.random.default_rng(0))
    problem.close()
    noise = NoiseTable.create(0, max(1 << 20, 4 * theta.size), shared=shared or workers > 1)
    evaluator = build(spec, workers, noise, theta.size)
    tasks = generation_tasks(args.popsize, theta.size, noise, np.random.default_rng(1))
    training_rate(evaluator, theta, args.sigma, tasks)  # warm-up: compilation, first resets
    return evaluator, noise, theta, tasks


def raw_environment(spec: ProblemSpec, preprocessed: bool) -> gym.Env:
    if preprocessed:  # every wrapper of the training's environment but the action mapping
        return make_env(spec.env_ids[0], preprocessing=preprocessing(spec.policy))[0].env
    with quiet_output():
        env = gym.make(spec.env_ids[0])
        env.reset(seed=0)
    return env


def measure_ratio(args, spec: ProblemSpec, preprocessed: bool) -> tuple[list[tuple[float, float]], float, int]:
    """Per round, (raw, training) steps per CPU second over the same episodes, alternating episode by
    episode so that both see the same moments of the machine's drift; the policy's seconds per step;
    the steps of one round."""
    evaluator, noise, theta, tasks = setup(args, spec, 1)
    raw_env = raw_environment(spec, preprocessed)
    rates = []
    try:
        episodes, act_seconds = record_actions(evaluator, theta, args.sigma, tasks, preprocessed)
        steps = sum(len(actions) for _, actions in episodes)
        for _ in range(args.rounds):
            raw_seconds = trained_seconds = 0.0
            for index, (seed, actions) in enumerate(episodes):
                raw_seconds += replay(raw_env, seed, actions, preprocessed)
                started = time.process_time()
                evaluator.evaluate(Generation(0, theta, args.sigma, tasks[index:index + 1]))
                trained_seconds += time.process_time() - started
            rates.append((steps / raw_seconds, steps / trained_seconds))
    finally:
        evaluator.close()
        noise.close()
        raw_env.close()
    return rates, act_seconds, steps


def measure_scaling(args, spec: ProblemSpec) -> tuple[list[float], list[float]]:
    """Training env steps per second in all, with 1 and with 2 workers, one value each per round (wall
    time), the two alternating round by round (which goes first too) so that the machine's drift falls on
    both."""
    one, noise, theta, tasks = setup(args, spec, 1, shared=True)
    two = build(spec, 2, noise, theta.size)
    training_rate(two, theta, args.sigma, tasks)  # warm-up: the workers' compilation, first resets
    rates: dict[int, list[float]] = {1: [], 2: []}
    try:
        for index in range(args.rounds):
            pair = ((1, one), (2, two)) if index % 2 == 0 else ((2, two), (1, one))
            for workers, evaluator in pair:
                rates[workers].append(workers * training_rate(evaluator, theta, args.sigma, tasks))
    finally:
        one.close()
        two.close()
        noise.close()
    return rates[1], rates[2]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--environment", default="HalfCheetah-v5")
    parser.add_argument("--policy", choices=("static", "hebbian"), default="static")
    parser.add_argument("--hebb_rule", default="ABCD_lr")
    parser.add_argument("--init_weights", default="uni")
    parser.add_argument("--network", choices=tuple(NETWORKS), default="default", help="static networks: the shape")
    parser.add_argument("--scaling", action="store_true", help="compare 1 and 2 workers instead")
    parser.add_argument("--popsize", type=int, default=8, help="episodes per measured generation")
    parser.add_argument("--sigma", type=float, default=0.1)
    parser.add_argument("--rounds", type=int, default=5)
    add_results_flag(parser)
    args = parser.parse_args()
    env_id = envs.resolve_env_id(args.environment)
    spec = ProblemSpec((env_id,), PolicySettings(args.policy, args.hebb_rule, args.init_weights, network=args.network))
    label = f"{env_id}, {args.policy}" + (f" {args.hebb_rule}" if args.policy == "hebbian" else "")
    label += f" --network {args.network}" if args.network != "default" else ""
    name = f"throughput-{env_id}-{args.policy}" + ("-" + args.network if args.network != "default" else "")
    record = Record(name + ("-scaling" if args.scaling else ""), ("ale-py",))
    if args.scaling:
        one, two = measure_scaling(args, spec)
        speedups = [b / a for a, b in zip(one, two)]
        record.add("one_worker", f"{label}: training env steps per second, 1 worker", "steps/s", one)
        record.add("two_workers", f"{label}: training env steps per second, 2 workers in all", "steps/s", two)
        record.add("speedup", f"{label}: speed-up from 1 to 2 workers", "x", speedups)
        print(f"{label}: 1 worker {statistics.median(one):,.0f} steps/s, 2 workers {statistics.median(two):,.0f} "
              "steps/s in all")
        print(f"speed-up 1 -> 2 workers: {statistics.median(speedups):.2f}x (rounds: "
              + ", ".join(f"{speedup:.2f}" for speedup in speedups) + ")")
        record.write(args.results)
        return 0
    probe = spec.build()
    preprocessed = probe.net.pixels
    probe.close()
    rates, act_seconds, steps = measure_ratio(args, spec, preprocessed)
    raw = "the environment with the same preprocessing" if preprocessed else "raw env.step"
    ratios = [trained / raw for raw, trained in rates]
    record.add("training_rate", f"{label}: training loop, env steps per CPU second", "steps/s",
               [rate[1] for rate in rates])
    record.add("raw_rate", f"{label}: {raw}, env steps per CPU second", "steps/s", [rate[0] for rate in rates])
    record.add("ratio", f"{label}: training loop / {raw}, the same {steps} steps per round", "", ratios)
    record.add("policy", f"{label}: the policy's CPU time per step, over one pass", "us", [act_seconds * 1e6])
    print(f"{label}, 1 worker: training loop against {raw}, the same {steps} steps per round (CPU time)")
    print(f"steps per second: training {statistics.median(rate[1] for rate in rates):,.0f}, raw "
          f"{statistics.median(rate[0] for rate in rates):,.0f}; policy {act_seconds * 1e6:.0f} µs per step")
    print(f"ratio training / raw: {statistics.median(ratios):.3f} (rounds: "
          + ", ".join(f"{ratio:.2f}" for ratio in ratios) + ")")
    record.write(args.results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
