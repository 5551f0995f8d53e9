#!/usr/bin/env python
"""The quadruped against the environment the original ran: ``pybullet_envs``, gym-based.

    python experiments/original_ant.py results/paper/ant_hebbian_seed1 --episodes 100

The original's episode and this tool's, stepped alike, are ``experiments/original_envs.py``'s.

Here that episode is written out from the original's loop (``OriginalAnt``), beside this tool's (``ToolAnt``:
``envs.make_env``, the batched class and the recipe's wrappers), so that the same actions can be given to both from the
same reset and every step compared (``tests/test_original_ant.py``), and a run's agent scored on both
(``paired_scores``, this script): the same episode seeds, the same network (this tool's policy, its initial Hebbian
weights drawn from the episode's seed), the environment alone differing. Seeding the original's class (``env.seed``,
which its code never called) gives it the initial joint angles that ``reset(seed=...)`` gives the port's: the pinned
gym draws them from the same generator as Gymnasium.

The results of the comparison are in docs/original.md, "The original's quadruped, side by side".
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from envs import episode_rng
from experiments.original_envs import (
    BODIES,
    BURN_IN,
    MAX_EPISODE_STEPS,
    OriginalAnt,
    OriginalUnavailable,
    ToolAnt,
    original_gym,
)
from settings import EPISODE_SEED_RANGE

CPU_CODE = ("NPY_DISABLE_CPU_FEATURES", "OPENBLAS_CORETYPE")  # the code numpy and OpenBLAS take, where set

# --- a run's agent ------------------------------------------------------------------------------------


@dataclass
class Agent:
    """A run folder's final centre, with the policy its config.json records."""
    run: Path
    kind: str
    policy: object
    params: np.ndarray

    def episode_state(self, seed: int):
        return self.policy.reset(self.params, episode_rng(seed))  # as envs.rollout: the episode's own stream

    def act(self, state, observation: np.ndarray):
        return self.policy.act(self.params, state, observation)


def run_folder(path: str | Path) -> Path:
    """A run folder, or the newest run of a folder of runs (``results/paper/ant_hebbian_seed1``)."""
    path = Path(path)
    if path.is_dir() and not (path / "config.json").is_file():
        runs = sorted(run for run in path.iterdir() if (run / "config.json").is_file())
        path = runs[-1] if runs else path
    if not (path / "config.json").is_file():
        raise ValueError(f"{path} is not a run folder (no config.json), nor a folder of run folders")
    return path


def load_agent(path: str | Path) -> Agent:
    """The final centre (``last.dat`` or ``last_coeffs.dat``) of a run of the quadruped."""
    from cli.config import TrainConfig
    from envs import ProblemSpec
    from es.files import load_dat, read_json
    from es.runfolder import named_file

    run = run_folder(path)
    try:
        config = TrainConfig.from_dict(read_json(run / "config.json"), str(run / "config.json"))
    except TypeError as error:  # a JSON value of another shape
        raise ValueError(f"{run / 'config.json'}: unreadable ({error})") from None
    if not set(config.env.env_ids) <= set(BODIES):
        raise ValueError(f"{run} trained on {', '.join(config.env.env_ids)}; this compares the quadrupeds "
                         f"{', '.join(BODIES)}")
    problem = ProblemSpec((BODIES[0],), config.policy).build()
    try:
        policy = problem.policy
        file = run / named_file("last", policy.roles[0])
        if not file.is_file():
            raise ValueError(f"{run} has no {file.name} (its training is not complete)")
        params = policy.load({policy.roles[0]: load_dat(file)})
    finally:
        problem.close()
    return Agent(run, config.policy.kind, policy, params)


# --- side by side -------------------------------------------------------------------------------------


@dataclass
class Comparison:
    """Two environments given the same actions from the same reset, step by step."""
    first_observations: tuple[np.ndarray, np.ndarray]
    observations: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    rewards: list[tuple[float, float]] = field(default_factory=list)
    ends: list[tuple[bool, bool]] = field(default_factory=list)

    def first_difference(self) -> int | None:
        """The first policy step (from 1) whose observation, reward or end differ; None: none did."""
        for index, ((a, b), (ra, rb), (ea, eb)) in enumerate(zip(self.observations, self.rewards, self.ends)):
            if a.tobytes() != b.tobytes() or ra != rb or ea != eb:
                return index + 1
        return None


def side_by_side(left, right, seed: int, steps: int, agent: Agent | None = None,
                 rng: np.random.Generator | None = None) -> Comparison:
    """Reset both with ``seed``, then up to ``steps`` policy steps of the same actions: the agent's, computed from
    ``left``'s observations, or uniform in [-1, 1] from ``rng``. Stops where either episode ends."""
    observation = left.reset(seed)
    comparison = Comparison((observation, right.reset(seed)))
    state = agent.episode_state(seed) if agent is not None else None
    for _ in range(steps):
        if agent is not None:
            action, state = agent.act(state, observation)
            action = np.array(action, dtype=np.float32)
        else:
            action = rng.uniform(-1, 1, 8).astype(np.float32)
        a, b = left.step(action), right.step(action)
        comparison.observations.append((a.observation, b.observation))
        comparison.rewards.append((a.reward, b.reward))
        comparison.ends.append((a.ends, b.ends))
        observation = a.observation
        if a.ends or b.ends:
            break
    return comparison


def episode_return(env, agent: Agent, seed: int) -> tuple[float, int]:
    """The agent's return (the sum of the progress rewards) and policy steps on ``env`` (an ``OriginalAnt`` or a
    ``ToolAnt``), from the reset with ``seed``, each environment seeing its own observations."""
    observation = env.reset(seed)
    state = agent.episode_state(seed)
    total, steps = 0.0, 0
    while True:
        action, state = agent.act(state, observation)
        step = env.step(np.array(action, dtype=np.float32))
        total, steps, observation = total + step.reward, steps + 1, step.observation
        if step.ends:
            return total, steps


def paired_scores(agent: Agent, env_id: str, episodes: int, seed: int) -> dict:
    """The agent's returns on the original's environment and on this tool's, episode seeds ``seed``, ``seed + 1``,
    ...: each pair starts from the same joint angles and the same initial weights."""
    original, tool = OriginalAnt(env_id), ToolAnt(env_id)
    try:
        pairs = [(episode_return(original, agent, seed + i), episode_return(tool, agent, seed + i))
                 for i in range(episodes)]
    finally:
        original.close()
        tool.close()
    return {"environment": env_id, "seeds": [seed + i for i in range(episodes)],
            "original": [a[0] for a, _ in pairs], "original_steps": [a[1] for a, _ in pairs],
            "tool": [b[0] for _, b in pairs], "tool_steps": [b[1] for _, b in pairs]}


def paired_interval(differences: np.ndarray, resamples: int = 10_000, seed: int = 0) -> tuple[float, float]:
    """A 95 % percentile bootstrap interval of the mean of paired differences."""
    rng = np.random.default_rng(seed)
    means = differences[rng.integers(0, differences.size, (resamples, differences.size))].mean(axis=1)
    return float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))


def lockstep_records(agent: Agent | None, env_id: str, seed: int, steps: int) -> list[dict]:
    """The original's environment beside the port's class and beside the batched one, the same actions (``agent``'s
    or random ones) from the reset with ``seed``: how far they agree."""
    entries = []
    for against, stock in (("port", True), ("batched", False)):
        original, tool = OriginalAnt(env_id), ToolAnt(env_id, stock=stock)
        try:
            comparison = side_by_side(original, tool, seed, steps, agent, np.random.default_rng(seed))
        finally:
            original.close()
            tool.close()
        first_original, first_tool = comparison.first_observations
        reset = np.abs(first_original.astype(np.float64) - first_tool)
        entries.append({"actions": agent.kind if agent else "random", "environment": env_id, "against": against,
                        "steps": len(comparison.rewards), "first_difference": comparison.first_difference(),
                        "reset_elements": np.flatnonzero(reset).tolist(), "reset_difference": float(reset.max())})
    return entries


def provenance(argv: list[str] | None) -> dict:
    """What a record of this comparison says about where it was made."""
    import os
    import subprocess
    from importlib.metadata import version

    from report.machine import cpu_model

    root = Path(__file__).resolve().parent.parent
    commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True).stdout.strip()
    return {"command": ["experiments/original_ant.py", *(sys.argv[1:] if argv is None else argv)], "commit": commit,
            "cpu": cpu_model(), "cpu_code": {name: os.environ.get(name) for name in CPU_CODE},
            "versions": {package: version(package) for package in ("gym", "pybullet", "numpy")}}


def summary_line(agent: Agent, scores: dict) -> str:
    original, tool = np.array(scores["original"]), np.array(scores["tool"])
    difference = tool - original
    low, high = paired_interval(difference)
    same = int(np.sum(original == tool))
    return (f"{agent.kind:<8} {scores['environment']:<26} {original.mean():9.1f} ± {original.std():6.1f}  "
            f"{tool.mean():9.1f} ± {tool.std():6.1f}  {difference.mean():+8.1f} [{low:+.1f}, {high:+.1f}]  "
            f"{same:>3} of {original.size}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="experiments/original_ant.py", description=__doc__.splitlines()[1])
    parser.add_argument("runs", nargs="+", metavar="RUN", help="run folders of the quadruped (or folders of runs)")
    parser.add_argument("--environment", default=",".join(BODIES),
                        help=f"comma-separated bodies (default: the three, {','.join(BODIES)})")
    parser.add_argument("--episodes", type=int, default=20, help="episodes per body and run (default: 20)")
    parser.add_argument("--seed", type=int, default=2**31, help="the first episode's seed (default: 2^31, the "
                        "campaign's evaluation seeds)")
    parser.add_argument("--steps", type=int, default=MAX_EPISODE_STEPS - BURN_IN,
                        help="policy steps of the same actions given to both (default: 960, a whole episode)")
    parser.add_argument("--json", default=None, metavar="PATH", help="also write every episode's returns here")
    args = parser.parse_args(argv)
    bodies = args.environment.split(",")
    try:
        for flag, value in (("--episodes", args.episodes), ("--steps", args.steps)):
            if value < 1:
                raise ValueError(f"{flag} {value}: give a whole number of at least 1")
        unknown = [body for body in bodies if body not in BODIES]
        if unknown:
            raise ValueError(f"--environment {unknown[0]}: unknown quadruped; valid: {', '.join(BODIES)}")
        low, high = EPISODE_SEED_RANGE
        if not low <= args.seed <= args.seed + args.episodes - 1 <= high:
            raise ValueError(f"--seed {args.seed} with --episodes {args.episodes}: the episodes' seeds must lie "
                             f"from {low} to {high}")
        if args.json and Path(args.json).exists():
            raise ValueError(f"--json {args.json} exists; give a new file")
        if args.json and not Path(args.json).resolve().parent.is_dir():
            raise ValueError(f"--json {args.json}: no folder {Path(args.json).parent}; give a file in a folder that "
                             "exists")
        original_gym()
        agents = [load_agent(run) for run in args.runs]
    except (ValueError, OriginalUnavailable) as error:
        print(f"{parser.prog}: error: {error}", file=sys.stderr)
        return 2
    records, lockstep = [], []
    for agent in [None, *agents]:
        for body in bodies:
            lockstep += lockstep_records(agent, body, args.seed, args.steps)
    print(f"{'actions':<8} {'environment':<26} {'against':<9} {'policy steps':>12}  first difference")
    for entry in lockstep:
        print(f"{entry['actions']:<8} {entry['environment']:<26} {entry['against']:<9} {entry['steps']:>12}  "
              f"{entry['first_difference'] or 'none'}")
    print(f"{'kind':<8} {'environment':<26} {'original':>18}  {'this tool':>18}  {'tool - original [95 %]':>26}  "
          "equal returns")
    for agent in agents:
        for body in bodies:
            scores = paired_scores(agent, body, args.episodes, args.seed)
            print(summary_line(agent, scores), flush=True)
            records.append({"run": str(agent.run), "kind": agent.kind, **scores})
    if args.json:
        try:
            Path(args.json).write_text(json.dumps({**provenance(argv), "episodes": args.episodes, "seed": args.seed,
                                                   "lockstep": lockstep, "scores": records}, indent=1) + "\n")
        except OSError as error:
            print(f"{parser.prog}: error: --json {args.json}: {error.strerror or error}", file=sys.stderr)
            return 2
    return 0

if __name__ == "__main__":
    sys.exit(main())
