#!/usr/bin/env python
"""Training-loop throughput against the raw speed of the environment, measured in one run.

    python benchmarks/throughput.py --environment HalfCheetah-v5 --policy static
    python benchmarks/throughput.py --environment HalfCheetah-v5 --policy hebbian --hebb_rule ABCD_lr
    python benchmarks/throughput.py --environment AntBulletEnv-v0 --policy static --scaling
    python benchmarks/throughput.py --environment ALE/Pong-v5 --network lstm
    python benchmarks/throughput.py --environment CarRacing-v3 --policy hebbian
    python benchmarks/throughput.py --environment HalfCheetah-v5 --policy hebbian --baseline DIR

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
--baseline DIR (a checkout of another commit: ``git worktree add DIR COMMIT``) measures the ratio with
today's code and with that checkout's, each in a process of its own that imports its checkout's modules
and runs this script's measuring code (``Side``), the two taking turns round by round.
Each run writes its record to benchmarks/results/ (benchmarks/record.py). Targets:
static MLP on HalfCheetah-v5 >= 0.85, Hebbian ABCD_lr >= 0.70 on HalfCheetah-v5 and >= 0.90 on
AntBulletEnv-v0 (--threads 1); 1 -> 2 workers on AntBulletEnv-v0 >= 1.8x (--scaling).

For image observations the preprocessing (Atari's frame skip, no-op starts, FIRE reset and frame
stack, or pytorch-es's 42 x 42 normalised frames) belongs to the environment's cost, not the
loop's: the raw side is then the environment as ``make_env`` builds it for the network (every
wrapper but the action mapping), replaying the actions the episodes chose, resets included. The
policy's own cost per step (``act``, CPU time) is printed too; the target for
``--network lstm``: <= 1 ms.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

# the checkout whose modules this process imports and measures: this one, or in a side process of --baseline
# the one named after --_side; and this one last where it is missing (benchmarks/record.py would put it first)
sys.path.insert(0, sys.argv[sys.argv.index("--_side") + 1] if "--_side" in sys.argv[:-1]
                else str(Path(__file__).resolve().parent.parent))
sys.path.append(str(Path(__file__).resolve().parent.parent))

import gymnasium as gym
from record import Record, add_results_flag

import envs
from envs import ProblemSpec, make_env, quiet_output
from es.backends import Generation, ProcessEvaluator, SerialEvaluator
from es.noise import NoiseTable
from es.worker import make_tasks
from policies import NETWORKS, PolicySettings, preprocessing

ROOT = Path(__file__).resolve().parent.parent
SIDE = "--_side"  # (internal) this process measures the checkout named after it: one side of --baseline


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
    session = RatioSession(args, spec, preprocessed)
    try:
        rates = [session.round() for _ in range(args.rounds)]
    finally:
        session.close()
    return rates, session.act_seconds, session.steps


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


# --- side by side with another checkout (--baseline) ----------------------------------------------

ANSWER = "@@side "  # a side's answers are the lines of its output that start so (libraries may print others)


class Side:
    """This script in a child process that imports another checkout's modules (``--_side ROOT``) and runs
    the measurements it is asked for, one JSON line each way: the same measuring code on both sides of a
    comparison, each side's own project code measured."""

    def __init__(self, script: str, root: Path, label: str):
        self.label = label
        self.process = subprocess.Popen([sys.executable, script, SIDE, str(root)], stdin=subprocess.PIPE,
                                        stdout=subprocess.PIPE, text=True, cwd=root)

    def ask(self, request: str, **arguments):
        assert self.process.stdin is not None and self.process.stdout is not None
        self.process.stdin.write(json.dumps([request, arguments]) + "\n")
        self.process.stdin.flush()
        for line in self.process.stdout:
            if line.startswith(ANSWER):
                return json.loads(line[len(ANSWER):])
        raise RuntimeError(f"the {self.label} side stopped (exit code {self.process.wait()}); its error is above")

    def close(self) -> None:
        if self.process.stdin is not None:
            self.process.stdin.close()
        try:
            self.process.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.process.kill()


def serve(requests: dict[str, Callable]) -> int:
    """A side's loop: each line of its input a request ``[name, arguments]``, answered on its output."""
    for line in sys.stdin:
        name, arguments = json.loads(line)
        print(ANSWER + json.dumps(requests[name](**arguments)), flush=True)
    return 0


def baseline_error(root: Path) -> str | None:
    """Why ``root`` cannot be --baseline's checkout of this project (another commit's worktree), or None."""
    if not all((root / name).is_dir() for name in ("envs", "policies", "es", "benchmarks")):
        return (f"--baseline {root}: not a checkout of this project (no envs/, policies/, es/ and benchmarks/ in it); "
                "make one with: git worktree add DIR COMMIT")
    return None


def sides(script: str, baseline: Path) -> dict[str, Side]:
    """The two sides of a comparison: this checkout's code and the baseline's."""
    return {"today": Side(script, ROOT, "today's"), "baseline": Side(script, baseline, "baseline's")}


def alternating(rounds: int, named: dict[str, Side], request: str, **arguments) -> dict[str, list]:
    """Each side's answers to ``request``, round by round, the two taking turns (which goes first too)."""
    answers: dict[str, list] = {name: [] for name in named}
    for index in range(rounds):
        order = list(named) if index % 2 == 0 else list(reversed(named))
        for name in order:
            answers[name].append(named[name].ask(request, **arguments))
    return answers


class RatioSession:
    """The training loop and the raw environment on the same episodes: the evaluator and the raw environment
    made once, the episodes' actions recorded, then a round on request (``measure_ratio``, a side's rounds)."""

    def __init__(self, args, spec: ProblemSpec, preprocessed: bool):
        self.args, self.preprocessed = args, preprocessed
        self.evaluator, self.noise, self.theta, self.tasks = setup(args, spec, 1)
        self.raw_env = raw_environment(spec, preprocessed)
        try:
            self.episodes, self.act_seconds = record_actions(self.evaluator, self.theta, args.sigma, self.tasks,
                                                             preprocessed)
        except BaseException:
            self.close()
            raise
        self.steps = sum(len(actions) for _, actions in self.episodes)

    def close(self) -> None:
        self.evaluator.close()
        self.noise.close()
        self.raw_env.close()

    def round(self) -> tuple[float, float]:
        """(raw, training) steps per CPU second over the recorded episodes, alternating episode by episode."""
        raw_seconds = trained_seconds = 0.0
        for index, (seed, actions) in enumerate(self.episodes):
            raw_seconds += replay(self.raw_env, seed, actions, self.preprocessed)
            started = time.process_time()
            self.evaluator.evaluate(Generation(0, self.theta, self.args.sigma, self.tasks[index:index + 1]))
            trained_seconds += time.process_time() - started
        return self.steps / raw_seconds, self.steps / trained_seconds


def side_requests(args) -> dict[str, Callable]:
    """What a side of ``--baseline`` answers: the ratio's set-up and its rounds."""
    session: dict[str, RatioSession] = {}

    def start(environment: str, policy: str, hebb_rule: str, init_weights: str, network: str, popsize: int,
              sigma: float) -> dict:
        args.popsize, args.sigma = popsize, sigma
        spec = ProblemSpec((envs.resolve_env_id(environment),), PolicySettings(policy, hebb_rule, init_weights,
                                                                               network=network))
        probe = spec.build()
        preprocessed = probe.net.pixels
        probe.close()
        session["ratio"] = RatioSession(args, spec, preprocessed)
        return {"steps": session["ratio"].steps, "policy_us": session["ratio"].act_seconds * 1e6}

    def ratio_round() -> list[float]:
        return list(session["ratio"].round())
    return {"start": start, "round": ratio_round}


def compare_with_baseline(args, record: Record, label: str, raw: str) -> None:
    """The loop/raw ratio of today's code and of the baseline's, measured in two side processes taking
    turns round by round."""
    named = sides(__file__, args.baseline)
    try:
        started = {name: side.ask("start", environment=args.environment, policy=args.policy,
                                  hebb_rule=args.hebb_rule, init_weights=args.init_weights, network=args.network,
                                  popsize=args.popsize, sigma=args.sigma) for name, side in named.items()}
        answers = alternating(args.rounds, named, "round")
    finally:
        for side in named.values():
            side.close()
    steps = started["today"]["steps"]
    for name, rounds in answers.items():
        suffix = "" if name == "today" else "_baseline"
        ratios = [training / raw_rate for raw_rate, training in rounds]
        record.add(f"training_rate{suffix}", f"{label}, {name}'s code: training loop, env steps per CPU second",
                   "steps/s", [training for _, training in rounds])
        record.add(f"raw_rate{suffix}", f"{label}, {name}'s code: {raw}, env steps per CPU second", "steps/s",
                   [raw_rate for raw_rate, _ in rounds])
        record.add(f"ratio{suffix}", f"{label}, {name}'s code: training loop / {raw}, the same {steps} steps per "
                   "round", "", ratios)
        record.add(f"policy{suffix}", f"{label}, {name}'s code: the policy's CPU time per step, over one pass", "us",
                   [started[name]["policy_us"]])
        print(f"{name}'s code ({args.baseline if name == 'baseline' else ROOT}): ratio training / raw "
              f"{statistics.median(ratios):.3f} (rounds: {', '.join(f'{ratio:.2f}' for ratio in ratios)}); policy "
              f"{started[name]['policy_us']:.0f} µs per step")
    record.note("baseline", str(args.baseline))


def main() -> int:
    if SIDE in sys.argv:
        parser = argparse.ArgumentParser()
        parser.add_argument(SIDE, type=Path)
        return serve(side_requests(parser.parse_args()))
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
    parser.add_argument("--baseline", type=Path, metavar="DIR",
                        help="also measure the ratio with the code of this checkout (git worktree add DIR COMMIT), "
                             "each side in a process of its own, the two taking turns round by round")
    add_results_flag(parser)
    args = parser.parse_args()
    if args.baseline is not None:
        args.baseline = args.baseline.expanduser().resolve()
        if error := baseline_error(args.baseline):
            print(f"error: {error}", file=sys.stderr)
            return 2
    env_id = envs.resolve_env_id(args.environment)
    spec = ProblemSpec((env_id,), PolicySettings(args.policy, args.hebb_rule, args.init_weights, network=args.network))
    label = f"{env_id}, {args.policy}" + (f" {args.hebb_rule}" if args.policy == "hebbian" else "")
    label += f" --network {args.network}" if args.network != "default" else ""
    name = f"throughput-{env_id}-{args.policy}" + ("-" + args.network if args.network != "default" else "")
    record = Record(name + ("-scaling" if args.scaling else "-against-baseline" if args.baseline else ""), ("ale-py",))
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
    raw = "the environment with the same preprocessing" if preprocessed else "raw env.step"
    if args.baseline is not None:
        compare_with_baseline(args, record, label, raw)
        record.write(args.results)
        return 0
    rates, act_seconds, steps = measure_ratio(args, spec, preprocessed)
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
