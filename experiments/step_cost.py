#!/usr/bin/env python
"""Expected wall time per generation of the paper's experiments, from the measured cost of a step.

    python experiments/step_cost.py --environment CarRacing-v0 --kind hebbian
    python experiments/step_cost.py --environment AntBulletEnv-v0,AntAsymRightBulletEnv-v0 --kind static

A real training run's first generations are no guide: random networks end their episodes early
(CarRacing after 21 steps without a new tile, the ant after step 201 + 31 steps without progress),
while a trained one runs all 1000 steps. So this measures, per environment, the CPU time of one
policy step (``policy.act`` + ``env.step`` through the recipe's wrappers, generation-0 parameters,
in the project's one episode loop, ``envs.rollout``) and of one reset (the ant's 40-step burn-in
included), in this process's CPU time so that other
load on the machine does not inflate it, and projects

    seconds per generation = (popsize + 1) x sum over envs (reset + length x step) / workers

for episodes of ``--length`` environment steps (1000, the TimeLimit, reached by a policy that
survives: 960 policy steps after the ant's burn-in). It ignores
the master's work and assumes the workers scale linearly (``benchmarks/throughput.py --scaling``
measures how far they do from 1 to 2).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from envs import ProblemSpec, episode_rng, resolve_env_id, rollout
from policies import KINDS, PolicySettings


def reset_cost(problem, env_index: int, resets: int = 5) -> float:
    """CPU seconds per reset: the environment's (the ant's burn-in included) and the policy's."""
    env, policy = problem.envs[env_index], problem.policy
    params = policy.initial_params(np.random.default_rng(0))
    started = time.process_time()
    for seed in range(resets):
        env.reset(seed=seed)
        policy.reset(params, episode_rng(seed))
    return (time.process_time() - started) / resets


def step_and_reset_cost(problem, env_index: int, steps: int) -> tuple[float, float]:
    """CPU seconds per policy step and per reset: whole episodes of the project's one loop
    (``envs.rollout``), the last one cut at ``steps`` policy steps, less their resets."""
    env, policy, burn_in = problem.envs[env_index], problem.policy, problem.recipes[env_index].burn_in
    params = policy.initial_params(np.random.default_rng(0))
    rollout(env, policy, params, seed=0, max_steps=burn_in + 1)  # untimed: the first act compiles the numba kernels
    reset = reset_cost(problem, env_index)
    done_steps, episodes, started = 0, 0, time.process_time()
    while done_steps < steps:
        episode = rollout(env, policy, params, seed=episodes, max_steps=burn_in + steps - done_steps)
        done_steps, episodes = done_steps + episode.steps - burn_in, episodes + 1
    return (time.process_time() - started - episodes * reset) / done_steps, reset


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument("--environment", required=True, help="comma-separated ids, as for training")
    parser.add_argument("--kind", choices=tuple(KINDS), default=PolicySettings.kind)
    parser.add_argument("--steps", type=int, default=1000, help="policy steps measured per environment")
    parser.add_argument("--popsize", type=int, default=200)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--length", type=int, default=1000,
                        help="environment steps per episode (burn-in included) to project for")
    args = parser.parse_args()
    env_ids = tuple(resolve_env_id(env_id) for env_id in args.environment.split(","))
    problem = ProblemSpec(env_ids, PolicySettings(args.kind)).build()
    try:
        costs = [step_and_reset_cost(problem, index, args.steps) for index in range(len(env_ids))]
        policy_steps = [args.length - recipe.burn_in for recipe in problem.recipes]
    finally:
        problem.close()
    for env_id, (step, reset) in zip(env_ids, costs):
        print(f"{env_id} ({args.kind}): {step * 1e3:.2f} ms CPU per policy step, {reset * 1e3:.1f} ms per reset")
    episode = sum(reset + length * step for (step, reset), length in zip(costs, policy_steps))
    seconds = (args.popsize + 1) * episode / args.workers
    print(f"projected: {seconds:.0f} s per generation ({seconds / 60:.1f} min) for popsize {args.popsize}, "
          f"{args.length}-step episodes on {len(env_ids)} environment(s), {args.workers} workers")
    return 0


if __name__ == "__main__":
    sys.exit(main())
