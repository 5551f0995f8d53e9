#!/usr/bin/env python
"""Gymnasium's CarRacing against the project's FastCarRacing, measured in one run (issue 9).

    python benchmarks/car_racing.py               # env and training-loop speed, the pixel policy's share
    python benchmarks/car_racing.py --identity    # and 20 long episodes compared frame by frame

Gymnasium's class is ``CarRacingStock-v3``, the project's ``CarRacing-v3``. Everything is timed in
CPU time of this process, the two classes alternating (round by round for the environment, episode
by episode for the training loop) so that this machine's drift (about +-40 %) and other load fall
on both alike; the medians over rounds are printed.

- environment: ``env.step`` of each class, the same seeds and random actions (resets untimed);
- training loop: the real evaluation path (serial evaluator, worker, recipe wrappers, network,
  rollout) on the same generation of tasks, static and Hebbian (ABCD_lr), generation-0 parameters,
  so early-stopped episodes, resets included; both classes must return the same fitness;
- the pixel policy's share of a step of the fast class: ``PixelObservation``'s resize, then the CNN
  and the dense head (and the Hebbian update), against ``env.step`` (all wrappers but the recipe's);
- ``--identity``: episodes of up to 1000 steps on seeds and drivers that no test uses (a
  track-following controller at two speeds, smoothed random driving, full throttle, braking),
  observations, rewards, flags and info compared at every step and ``rgb_array`` frames every
  ``--frame_every`` steps; exit code 1 on the first difference.

Targets: the environment >= 2.5x the stock class (aim 4x); the Hebbian training loop >= 2.5x
faster per step.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import envs  # noqa: E402  (headless defaults; CarRacing-v3 is the fast class)
import gymnasium as gym  # noqa: E402
from envs import ProblemSpec  # noqa: E402
from envs.make import STOCK_CAR_RACING_ID as STOCK_ID  # noqa: E402
from envs.wrappers import CarRacingAction, PixelObservation  # noqa: E402
from es.backends import Generation, SerialEvaluator  # noqa: E402
from policies import PolicySettings  # noqa: E402
from es.noise import NoiseTable  # noqa: E402
from throughput import generation_tasks  # noqa: E402  (benchmarks/throughput.py)

FAST_ID = "CarRacing-v3"
ENV_TARGET, LOOP_TARGET = 2.5, 2.5


def make(env_id: str, render_mode: str | None = None) -> gym.Env:
    with envs.quiet_output():
        return gym.make(env_id, render_mode=render_mode)


def random_actions(rng: np.random.Generator, steps: int) -> np.ndarray:
    """Steering as a smoothed random walk, gas and brake at random: the car turns, slides and stays around."""
    steer = np.clip(np.cumsum(rng.normal(0, 0.15, size=steps)), -1, 1)
    gas, brake = rng.uniform(0, 0.6, size=steps), np.where(rng.random(steps) < 0.1, rng.uniform(0, 1, steps), 0)
    return np.stack([steer, gas, brake], axis=1).astype(np.float32)


def timed_steps(env: gym.Env, seed: int, actions: np.ndarray) -> tuple[float, int]:
    """CPU seconds of ``env.step`` over ``actions`` from ``reset(seed)``, resetting (untimed) on an end."""
    env.reset(seed=seed)
    seconds = 0.0
    for action in actions:
        started = time.process_time()
        _, _, terminated, truncated, _ = env.step(action)
        seconds += time.process_time() - started
        if terminated or truncated:
            seed += 1000
            env.reset(seed=seed)
    return seconds, len(actions)


def env_rates(rounds: int, steps: int) -> tuple[list[float], list[float]]:
    """Steps per CPU second of each class, per round, the same seeds and actions for both."""
    stock, fast = make(STOCK_ID), make(FAST_ID)
    timed_steps(fast, 0, random_actions(np.random.default_rng(0), 5))  # warm-up: numba's compiled code
    stock_rates, fast_rates = [], []
    for round_index in range(rounds):
        actions = random_actions(np.random.default_rng(500 + round_index), steps)
        for env, rates in ((stock, stock_rates), (fast, fast_rates)):
            seconds, count = timed_steps(env, 500 + round_index, actions)
            rates.append(count / seconds)
    stock.close()
    fast.close()
    return stock_rates, fast_rates


def loop_rates(kind: str, rounds: int, popsize: int) -> tuple[list[float], list[float], float]:
    """Training-loop steps per CPU second with each class, per round, and the mean episode length."""
    specs = [ProblemSpec((env_id,), PolicySettings(kind)) for env_id in (STOCK_ID, FAST_ID)]
    problem = specs[0].build()
    theta = problem.policy.initial_params(np.random.default_rng(0))
    problem.close()
    noise = NoiseTable.create(0, max(1 << 20, 4 * theta.size))
    evaluators = [SerialEvaluator(spec.build, noise, theta.size, spec.env_ids) for spec in specs]
    tasks = generation_tasks(popsize, theta.size, noise, np.random.default_rng(1))
    for evaluator in evaluators:  # warm-up: compilation, first resets
        evaluator.evaluate(Generation(0, theta, 0.1, tasks[:1]))
    rates: list[list[float]] = [[], []]
    steps = 0
    try:
        for _ in range(rounds):
            seconds, steps = [0.0, 0.0], 0
            for number in range(len(tasks)):
                task, returns = tasks[number:number + 1], []
                for index, evaluator in enumerate(evaluators):
                    started = time.process_time()
                    results = evaluator.evaluate(Generation(0, theta, 0.1, task))
                    seconds[index] += time.process_time() - started
                    returns.append(results.returns[0])
                if returns[0] != returns[1]:
                    raise AssertionError(f"{kind}: the classes' fitness differ on task {task.tolist()}: {returns}")
                steps += int(results.steps[0])
            for index in range(2):
                rates[index].append(steps / seconds[index])
    finally:
        for evaluator in evaluators:
            evaluator.close()
        noise.close()
    return rates[0], rates[1], steps / len(tasks)


def policy_share(kind: str, steps: int) -> dict[str, float]:
    """CPU seconds per step of the fast class: env.step, the resize, the network (with its update)."""
    problem = ProblemSpec((FAST_ID,), PolicySettings(kind)).build()
    chain = problem.envs[0]
    wrappers = []
    while isinstance(chain, gym.Wrapper):
        wrappers.append(chain)
        chain = chain.env
    pixels = next(w for w in wrappers if isinstance(w, PixelObservation))
    squash = next(w for w in wrappers if isinstance(w, CarRacingAction))
    env, policy = pixels.env, problem.policy  # env: the fast class with Gymnasium's own wrappers
    params = policy.initial_params(np.random.default_rng(0))
    frame, _ = env.reset(seed=0)  # untimed warm-up: numba's kernels, torch's first convolution
    policy.act(params, policy.reset(params, np.random.default_rng(0)), pixels.observation(frame))
    totals = {"env.step": 0.0, "resize": 0.0, "network": 0.0}
    done, seed = 0, 0
    while done < steps:
        frame, _ = env.reset(seed=seed)
        state = policy.reset(params, np.random.default_rng(seed))
        for _ in range(min(300, steps - done)):  # the early stop left out: episodes of 300 steps
            started = time.process_time()
            observation = pixels.observation(frame)
            resized = time.process_time()
            output, state = policy.act(params, state, observation)
            acted = time.process_time()
            frame, _, terminated, truncated, _ = env.step(squash.action(output))
            stepped = time.process_time()
            totals["resize"] += resized - started
            totals["network"] += acted - resized
            totals["env.step"] += stepped - acted
            done += 1
            if terminated or truncated:
                break
        seed += 1
    problem.close()
    return {part: seconds / done for part, seconds in totals.items()}


def follow_track(speed: float):
    """A driver that steers toward the track six tiles ahead and holds ``speed``: it visits most tiles."""
    def act(car_racing, rng: np.random.Generator) -> np.ndarray:
        car, track = car_racing.car, np.array([point[2:4] for point in car_racing.track])
        x, y = car.hull.position
        nearest = int(np.argmin(np.hypot(track[:, 0] - x, track[:, 1] - y)))
        target_x, target_y = track[(nearest + 6) % len(track)]
        error = math.atan2(target_y - y, target_x - x) - (car.hull.angle + math.pi / 2)
        error = (error + math.pi) % (2 * math.pi) - math.pi
        velocity = float(np.hypot(*car.hull.linearVelocity))
        return np.array([np.clip(-2 * error, -1, 1), 0.4 if velocity < speed else 0.0,
                         0.3 if velocity > 1.3 * speed else 0.0], dtype=np.float32)
    return act


def wander(car_racing, rng: np.random.Generator) -> np.ndarray:
    return random_actions(rng, 1)[0]


def full_throttle(car_racing, rng: np.random.Generator) -> np.ndarray:
    return np.array([rng.uniform(-0.3, 0.3), 1.0, 0.0], dtype=np.float32)


def stop_and_go(car_racing, rng: np.random.Generator) -> np.ndarray:
    braking = int(car_racing.t * 50) % 80 >= 50
    return np.array([rng.uniform(-1, 1), 0.0 if braking else 0.8, 0.9 if braking else 0.0], dtype=np.float32)


DRIVERS = {"follow the track at 40": follow_track(40.0), "follow the track at 60": follow_track(60.0),
           "wander": wander, "full throttle": full_throttle, "stop and go": stop_and_go}


def identity(episodes: int, frame_every: int) -> bool:
    """Both classes side by side on seeds 7000, 7001, ...; True if every step and frame matched."""
    stock, fast = make(STOCK_ID, "rgb_array"), make(FAST_ID, "rgb_array")
    drivers = list(DRIVERS.items())
    try:
        for episode in range(episodes):
            seed = 7000 + episode
            name, driver = drivers[episode % len(drivers)]
            rng = np.random.default_rng(seed)
            same = [np.array_equal(a, b) for a, b in zip(stock.reset(seed=seed)[:1], fast.reset(seed=seed)[:1])]
            total, step, end = 0.0, 0, "1000 steps"
            while all(same):
                action = driver(stock.unwrapped, rng)
                expected, got = stock.step(action), fast.step(action)
                same = [np.array_equal(expected[0], got[0]), expected[1:] == got[1:]]
                if step % frame_every == 0:
                    same.append(np.array_equal(stock.render(), fast.render()))
                total, step = total + expected[1], step + 1
                if expected[2] or expected[3]:
                    end = "terminated" if expected[2] else "truncated"
                    break
            print(f"  seed {seed} ({name}): {step} steps, {end}, return {total:.1f}: "
                  + ("identical" if all(same) else f"DIFFERENT at step {step}"))
            if not all(same):
                return False
    finally:
        stock.close()
        fast.close()
    return True


def summary(label: str, stock: list[float], fast: list[float], target: float | None = None) -> None:
    ratios = [f / s for s, f in zip(stock, fast)]
    goal = f" (target >= {target}x)" if target else ""
    print(f"{label}: stock {statistics.median(stock):,.0f}, fast {statistics.median(fast):,.0f} steps per CPU "
          f"second; ratio {statistics.median(ratios):.2f}x{goal} (rounds: {', '.join(f'{r:.2f}' for r in ratios)})")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=300, help="environment steps per class and round")
    parser.add_argument("--popsize", type=int, default=8, help="episodes per training-loop round")
    parser.add_argument("--share_steps", type=int, default=600, help="steps measured for the policy's share")
    parser.add_argument("--identity", action="store_true", help="also compare long episodes frame by frame")
    parser.add_argument("--episodes", type=int, default=20, help="with --identity: how many episodes")
    parser.add_argument("--frame_every", type=int, default=50, help="with --identity: compare render() this often")
    args = parser.parse_args()
    for name in ("rounds", "steps", "popsize", "share_steps", "episodes", "frame_every"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be at least 1, got {getattr(args, name)}")
    summary("environment (env.step)", *env_rates(args.rounds, args.steps), ENV_TARGET)
    for kind in ("static", "hebbian"):
        stock, fast, length = loop_rates(kind, args.rounds, args.popsize)
        summary(f"training loop, {kind} (mean episode {length:.0f} steps)", stock, fast,
                LOOP_TARGET if kind == "hebbian" else None)
    for kind in ("static", "hebbian"):
        parts = policy_share(kind, args.share_steps)
        total = sum(parts.values())
        print(f"pixel policy, {kind}: {1e3 * total:.2f} ms CPU per step of the fast class: "
              + ", ".join(f"{part} {1e3 * seconds:.2f} ms ({seconds / total:.0%})" for part, seconds in parts.items())
              + f"; the policy (resize + network) is {(parts['resize'] + parts['network']) / total:.0%} of a step")
    if args.identity:
        print(f"identity: {args.episodes} episodes of up to 1000 steps, frames every {args.frame_every} steps")
        if not identity(args.episodes, args.frame_every):
            return 1
        print("identity: every observation, reward, flag, info and compared frame identical")
    return 0


if __name__ == "__main__":
    sys.exit(main())
