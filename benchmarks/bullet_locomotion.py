#!/usr/bin/env python
"""pyBullet's walkers against the batched classes of ``envs.bullet_locomotion``, measured in one run.

    python benchmarks/bullet_locomotion.py
    python benchmarks/bullet_locomotion.py --environment AntBulletEnv-v0 --rounds 7

For each walker, ``env.step`` of pyBullet's own class (``*BulletStockEnv-v0``) and of the batched one
(``*BulletEnv-v0``), the same seeds and random actions for both, resets untimed, the two alternating
every 25 steps; then the training loop of the paper's damaged-ant experiment (the pyBullet ant
recipe, a Hebbian ABCD_lr network, one serial worker) over the same generation of episodes on each
class, alternating round by round, which must give the same returns. Everything is timed in CPU
time of this process and the medians over rounds are printed, with their range. Each run writes
its record to benchmarks/results/ (benchmarks/record.py).

Target: the ant's ``env.step`` >= 1.3x pyBullet's own class.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from car_racing import summary, timed_steps
from record import Record, add_results_flag
from throughput import setup

from cli.flags import positive_int
from envs import ProblemSpec, quiet_output
from envs.bullet_locomotion import FAST_IDS, STOCK_IDS
from es.backends import Generation
from policies import PolicySettings

ANT_TARGET = 1.3


def env_rates(env_id: str, rounds: int, steps: int, chunk: int = 25) -> tuple[list[float], list[float]]:
    """Steps per CPU second of the stock and the fast class of ``env_id``, per round."""
    import gymnasium as gym

    with quiet_output():
        stock, fast = gym.make(STOCK_IDS[env_id]), gym.make(env_id)
    size = stock.action_space.shape[0]
    stock_rates, fast_rates = [], []
    try:
        for round_index in range(rounds):
            rng = np.random.default_rng(700 + round_index)
            actions = rng.uniform(-1, 1, size=(steps, size)).astype(np.float32)
            chunks = zip(timed_steps(stock, 700 + round_index, actions, chunk),
                         timed_steps(fast, 700 + round_index, actions, chunk))
            stock_seconds, fast_seconds = (sum(seconds) for seconds in zip(*chunks))
            stock_rates.append(steps / stock_seconds)
            fast_rates.append(steps / fast_seconds)
    finally:
        stock.close()
        fast.close()
    return stock_rates, fast_rates


def loop_rates(rounds: int, popsize: int) -> tuple[list[float], list[float], float]:
    """Training-loop env steps per CPU second on each class, per round, and the mean episode length."""
    args = SimpleNamespace(popsize=popsize, sigma=0.1)
    policy = PolicySettings("hebbian", "ABCD_lr", "uni")
    runs = {env_id: setup(args, ProblemSpec((env_id,), policy), 1)
            for env_id in (STOCK_IDS["AntBulletEnv-v0"], "AntBulletEnv-v0")}
    rates: dict[str, list[float]] = {env_id: [] for env_id in runs}
    fitness, steps = {}, 0
    try:
        for _ in range(rounds):
            for env_id, (evaluator, _, theta, tasks) in runs.items():
                started = time.process_time()
                results = evaluator.evaluate(Generation(0, theta, args.sigma, tasks))
                rates[env_id].append(results.steps.sum() / (time.process_time() - started))
                fitness[env_id], steps = results.returns.tobytes(), int(results.steps.sum())
            if len(set(fitness.values())) != 1:
                raise SystemExit("the two classes gave different returns: not the same environment")
    finally:
        for evaluator, noise, _, _ in runs.values():
            evaluator.close()
            noise.close()
    stock, fast = rates.values()
    return stock, fast, steps / popsize


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--environment", choices=FAST_IDS, action="append",
                        help="a walker to time (repeatable; default: all four)")
    parser.add_argument("--rounds", type=positive_int, default=5)
    parser.add_argument("--steps", type=positive_int, default=1000, help="environment steps per class and round")
    parser.add_argument("--popsize", type=positive_int, default=4, help="episodes per training-loop round")
    add_results_flag(parser)
    args = parser.parse_args()
    record = Record("bullet_locomotion", ("pybullet-envs-gymnasium",))
    for env_id in args.environment or FAST_IDS:
        key = "env_step_" + env_id.removesuffix("BulletEnv-v0").lower()
        summary(record, key, f"{env_id} (env.step)", *env_rates(env_id, args.rounds, args.steps),
                ANT_TARGET if env_id == "AntBulletEnv-v0" else None, stock_name="pyBullet's")
    stock, fast, length = loop_rates(args.rounds, args.popsize)
    summary(record, "loop_ant_hebbian", f"training loop, AntBulletEnv-v0, Hebbian ABCD_lr, 1 worker (mean episode "
            f"{length:.0f} steps)", stock, fast, stock_name="pyBullet's")
    print(f"medians of {args.rounds} rounds; ranges in the record")
    record.write(args.results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
