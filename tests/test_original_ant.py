"""The quadruped against the environment the original ran (experiments/original_ant.py): pyBullet's own gym-based
``pybullet_envs`` under the old gym, stepped as the original's fitness function stepped it (a fresh environment per
episode, 40 zero actions, the progress reward, its stop rule), beside this tool's ant bodies, the same actions from the
same reset: random actions, the shipped static agent's and the shipped Hebbian agent's, on the standard body and on the
two damaged ones built from ``damaged_bullet_morphologies/`` as the original's README describes.

- pyBullet's port (``AntBulletStockEnv-v0`` and the stock damaged class, as ``envs.make_env`` wraps them) gives the
  original's observation, progress reward and end at every step, on any CPU;
- this tool's batched class gives them too with the code numpy and OpenBLAS take on an AVX2 CPU (the class computes
  as that code does on every CPU, docs/reproducibility.md), so the side by side runs in a child process taking it;
- the one difference: the observation the reset returns, the policy's first input. The original made its
  environment afresh for every episode, and pyBullet's first reset averages the body's parts without the floor into
  the angle to the target; this tool resets a warmed-up environment. Only that angle's sine differs, by less than
  1e-6; its effect on a shipped agent's score is measured in docs/original.md.

Needs the original extra (``pip install -r requirements-original.txt``); skipped without it.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.extras import need_module_level

need_module_level("original")

from envs import damaged  # noqa: E402
from experiments import original_ant, original_envs  # noqa: E402
from tests.test_bullet_locomotion import AVX2_STOCK, cpu_flags  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SEED = 2**31  # the campaign's first evaluation seed
STEPS = 250  # policy steps per comparison: random actions and the static agent end by step 210
RUNS = {"static": ROOT / "results" / "paper" / "ant_static_seed1", "hebbian": ROOT / "results" / "paper" /
        "ant_hebbian_seed1"}
SINE_OF_THE_ANGLE = 1  # the observation's element that a first reset computes without the floor


def comparisons(against: str) -> list[dict]:
    """Every body, every source of actions: the original's environment beside this tool's (``against``: the port's
    class or the batched one)."""
    agents = [None, *(original_ant.load_agent(run) for run in RUNS.values())]
    stock = against == "port"
    seen = []
    for body in original_envs.BODIES:
        original, tool = original_envs.OriginalAnt(body), original_envs.ToolAnt(body, stock=stock)
        try:
            for agent in agents:
                comparison = original_ant.side_by_side(original, tool, SEED, STEPS, agent, np.random.default_rng(3))
                first_original, first_tool = comparison.first_observations
                seen.append({
                    "body": body, "actions": agent.kind if agent else "random", "steps": len(comparison.rewards),
                    "first_difference": comparison.first_difference(),
                    "reset_elements": np.flatnonzero(first_original != first_tool).tolist(),
                    "reset_difference": float(np.abs(first_original.astype(np.float64) - first_tool).max()),
                    "rewards": [reward for reward, _ in comparison.rewards],
                    "ends": [bool(end) for end, _ in comparison.ends],
                    "dtypes": sorted({str(a.dtype) + str(b.dtype) for a, b in comparison.observations})})
        finally:
            original.close()
            tool.close()
    return seen


def check_every_step(seen: list[dict]) -> None:
    for entry in seen:
        where = f"{entry['body']}, {entry['actions']} actions"
        assert entry["first_difference"] is None, where
        assert entry["dtypes"] == ["float32float32"], where
        assert entry["reset_elements"] == [SINE_OF_THE_ANGLE] and 0 < entry["reset_difference"] < 1e-6, where
    # the comparisons reach the episodes' ends and the walking gait: the stop rule, done from step 202 on, and
    # the Hebbian agent walking forward on the bodies it trained on
    ends = {(entry["body"], entry["actions"]): entry for entry in seen}
    for body in original_envs.BODIES:
        for actions in ("random", "static"):
            entry = ends[body, actions]
            assert entry["ends"][-1] and not any(entry["ends"][:-1]) and entry["steps"] >= 202, (body, actions)
    for body in original_envs.BODIES[:2]:
        entry = ends[body, "hebbian"]
        assert entry["steps"] == STEPS and sum(entry["rewards"]) > 100, body


def test_the_ports_class_is_the_originals_at_every_step():
    check_every_step(comparisons("port"))


def test_the_batched_class_is_the_originals_at_every_step_with_an_avx2_cpus_code():
    if not {"avx2", "fma"} <= cpu_flags():
        pytest.skip("pyBullet's classes give the batched class's numbers with an AVX2 CPU's code; this CPU has no AVX2")
    code = ("import json; from tests.test_original_ant import comparisons; "
            "print(json.dumps(comparisons('batched')))")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env={**os.environ, **AVX2_STOCK},
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    check_every_step(json.loads(done.stdout.strip().splitlines()[-1]))


def test_the_damaged_bodies_load_their_files():
    """The original's damaged ants stand on their own legs: the files' shortened lower leg, nothing else changed."""
    firsts = {}
    for body in original_envs.BODIES:
        env = original_envs.OriginalAnt(body)
        try:
            env.reset(SEED)
            robot = env.unwrapped.robot
            side = damaged.BULLET_IDS.get(body)
            expected = damaged.bullet_xml(side) if side else "ant.xml"
            assert robot.model_xml == str(expected)
            firsts[body] = np.array(robot.body_real_xyz)
        finally:
            env.close()
    standard, right, left = (firsts[body] for body in original_envs.BODIES)
    assert not np.array_equal(standard, right) and not np.array_equal(standard, left)


def test_the_script_scores_an_agent_on_both_and_refuses_bad_input(tmp_path):
    out = tmp_path / "scores.json"
    script = [sys.executable, "experiments/original_ant.py"]
    done = subprocess.run([*script, str(RUNS["static"]), "--environment", "AntAsymLeftBulletEnv-v0", "--episodes", "2",
                           "--steps", "20", "--json", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    record = json.loads(out.read_text())
    (scores,) = record["scores"]
    assert scores["environment"] == "AntAsymLeftBulletEnv-v0" and scores["seeds"] == [SEED, SEED + 1]
    assert len(scores["original"]) == len(scores["tool"]) == 2 and all(steps >= 202 for steps in scores["tool_steps"])
    assert {entry["against"] for entry in record["lockstep"]} == {"port", "batched"}
    assert record["versions"]["gym"] == "0.23.1"
    for argv, message in ((["--episodes", "0"], "--episodes 0: give a whole number of at least 1"),
                          (["--environment", "Ant-v5"], "--environment Ant-v5: unknown quadruped"),
                          (["--json", str(out)], f"--json {out} exists"),
                          (["--seed", "-1"], "--seed -1 with --episodes 20: the episodes' seeds must lie from 0"),
                          (["--json", str(tmp_path / "no" / "x.json")], "no folder"),
                          ([str(tmp_path)], f"{tmp_path} is not a run folder")):
        runs = [] if argv[0].startswith("/") else [str(RUNS["static"])]
        done = subprocess.run([*script, *runs, *argv], cwd=ROOT, capture_output=True, text=True, timeout=600)
        assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
        assert message in done.stderr
