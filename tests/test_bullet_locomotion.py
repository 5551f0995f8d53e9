"""pyBullet's walkers stepped with batched queries (envs/bullet_locomotion.py) against pyBullet's own
classes, side by side:

- every walker the module speeds up, and both damaged ants, give the same observations (byte for
  byte), rewards, episode ends, contacts and torso pose as the stock class, over several episodes
  with reseeded resets and actions beyond [-1, 1] (clipped by both), the batched path being the one
  that ran;
- a walker that applies its own torques (the humanoid) keeps pyBullet's step, with the same numbers;
- the registered ids make the fast classes, the ``*BulletStockEnv-v0`` ids pyBullet's own, with the
  same spec otherwise; the fast classes are found by module and name, as workers and pickle find them;
- a rendered frame of the fast class equals the stock class's.

pyBullet's class leaves a few operations to numpy's and OpenBLAS's choice of code for the CPU; the fast class
computes them as that code does on an x86-64 CPU with AVX2 and FMA but without AVX-512 (the module's
docstring). So the side-by-side runs are made in a child process that takes that code on any such CPU: numpy's
AVX-512 loops turned off, OpenBLAS's Haswell kernels asked for.
"""

import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pybullet_envs_gymnasium.gym_locomotion_envs as locomotion
import pytest

import envs
from envs import bullet_locomotion, damaged
from envs.make import quiet_output

STOCK_CLASSES = {env_id: getattr(locomotion, gym.spec(stock_id).entry_point.rpartition(":")[2])
                 for env_id, stock_id in bullet_locomotion.STOCK_IDS.items()}


def pair(env_id: str):
    """(stock, fast) instances of ``env_id``'s class."""
    with quiet_output():
        if env_id in damaged.BULLET_IDS:
            xml = str(damaged.bullet_xml(damaged.BULLET_IDS[env_id]))
            return damaged.damaged_bullet_ant_class(stock=True)(xml), damaged.damaged_bullet_ant_class()(xml)
        stock = getattr(locomotion, gym.spec(env_id).entry_point.rpartition(":")[2])
        return stock(), bullet_locomotion.fast_class(stock)()


def run_side_by_side(env_id: str, steps: int, episode_steps: int) -> dict:
    stock, fast = pair(env_id)
    rng = np.random.default_rng(7)
    size = stock.action_space.shape[0]
    seen = {"episodes": 0, "terminated": 0, "contacts": set(), "batched": []}
    for env in (stock, fast):
        env.reset(seed=11)
    seen["batched"].append(fast._plan is not None)
    length = 0
    for _ in range(steps):
        action = (rng.normal(size=size) * 1.2).astype(np.float32)  # about a third of them beyond [-1, 1]
        obs_a, reward_a, term_a, trunc_a, _ = stock.step(action)
        obs_b, reward_b, term_b, trunc_b, _ = fast.step(action)
        assert obs_a.dtype == obs_b.dtype and obs_a.tobytes() == obs_b.tobytes()
        assert (reward_a, term_a, trunc_a) == (reward_b, term_b, trunc_b)
        assert stock.rewards == fast.rewards
        assert stock.robot.feet_contact.tobytes() == fast.robot.feet_contact.tobytes()
        assert np.array_equal(stock.robot.body_real_xyz, fast.robot.body_real_xyz)
        assert stock.robot.body_xyz == fast.robot.body_xyz and stock.robot.body_rpy == fast.robot.body_rpy
        seen["contacts"].update(fast.robot.feet_contact.tolist())
        length += 1
        if term_a or length == episode_steps:
            seen["episodes"] += 1
            seen["terminated"] += bool(term_a)
            seed = int(rng.integers(2**31))
            first_a, _ = stock.reset(seed=seed)
            first_b, _ = fast.reset(seed=seed)
            assert first_a.tobytes() == first_b.tobytes()
            seen["batched"].append(fast._plan is not None)
            length = 0
    for env in (stock, fast):
        env.close()
    return seen


ROOT = Path(__file__).resolve().parent.parent
AVX2_STOCK = {"NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR", "OPENBLAS_CORETYPE": "Haswell"}


def cpu_flags() -> set[str]:
    try:
        info = Path("/proc/cpuinfo").read_text()
    except OSError:
        return set()
    return set(next((line.split(":", 1)[1].split() for line in info.splitlines() if line.startswith("flags")), []))


def side_by_side_on_avx2(env_id: str, steps: int, episode_steps: int) -> dict:
    """``run_side_by_side`` in a child process whose numpy and OpenBLAS take an AVX2 CPU's code."""
    if platform.machine() != "x86_64" or not {"avx2", "fma"} <= cpu_flags():
        pytest.skip("pyBullet's class gives the fast class's numbers with an AVX2 CPU's code; this CPU has no AVX2")
    code = ("import json, sys; from tests.test_bullet_locomotion import run_side_by_side; "
            "seen = run_side_by_side(*json.loads(sys.argv[1])); "
            "print(json.dumps({**seen, 'contacts': sorted(seen['contacts'])}))")
    done = subprocess.run([sys.executable, "-c", code, json.dumps([env_id, steps, episode_steps])], cwd=ROOT,
                          env={**os.environ, **AVX2_STOCK}, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    return {**seen, "contacts": set(seen["contacts"])}


@pytest.mark.parametrize("env_id", [*bullet_locomotion.FAST_IDS, *damaged.BULLET_IDS])
def test_the_batched_step_gives_pybullets_numbers(env_id):
    seen = side_by_side_on_avx2(env_id, steps=360, episode_steps=120)
    assert all(seen["batched"])
    assert seen["episodes"] >= 3
    assert seen["contacts"] == {0.0, 1.0}  # feet on and off the ground, through the batched contact query


def test_episodes_that_end_by_falling_match_too():
    seen = side_by_side_on_avx2("HopperBulletEnv-v0", steps=300, episode_steps=1000)
    assert seen["terminated"] >= 3 and all(seen["batched"])


def test_a_walker_with_its_own_torques_keeps_pybullets_step():
    seen = side_by_side_on_avx2("HumanoidBulletEnv-v0", steps=40, episode_steps=20)
    assert not any(seen["batched"])


@pytest.mark.parametrize("env_id, stock_id", bullet_locomotion.STOCK_IDS.items())
def test_ids_make_the_fast_class_and_the_stock_one(env_id, stock_id):
    fast, stock = gym.spec(env_id), gym.spec(stock_id)
    assert fast.entry_point == f"envs.bullet_locomotion:{stock.entry_point.rpartition(':')[2]}"
    assert stock.entry_point.startswith("pybullet_envs_gymnasium.gym_locomotion_envs:")
    assert (fast.max_episode_steps, fast.reward_threshold, fast.kwargs) == \
           (stock.max_episode_steps, stock.reward_threshold, stock.kwargs)
    made, _ = envs.make_env(env_id)
    try:
        assert isinstance(made.unwrapped, bullet_locomotion.FastWalker)
        assert isinstance(made.unwrapped, STOCK_CLASSES[env_id])
        made_class = type(made.unwrapped)  # found by module and name, as workers and pickle find it
        assert made_class.__module__ == bullet_locomotion.__name__
        assert getattr(bullet_locomotion, made_class.__qualname__) is made_class
    finally:
        made.close()
    made, _ = envs.make_env(stock_id)
    try:
        assert type(made.unwrapped) is STOCK_CLASSES[env_id]
    finally:
        made.close()


def test_an_unknown_name_is_not_a_fast_class():
    with pytest.raises(AttributeError, match="no attribute 'CarRacing'"):
        bullet_locomotion.CarRacing  # noqa: B018


def test_a_rendered_frame_is_the_stock_classs():
    frames = []
    for env_id in ("AntBulletStockEnv-v0", "AntBulletEnv-v0"):
        with quiet_output():
            env = gym.make(env_id, render_mode="rgb_array")
        env.reset(seed=5)
        for _ in range(30):
            env.step(np.full(8, 0.5, dtype=np.float32))
        frames.append(env.render())
        env.close()
    assert frames[0].shape == frames[1].shape and frames[0].tobytes() == frames[1].tobytes()


def episode_digest(env_id: str, steps: int) -> str:
    """sha256 of the fast class's observations, rewards and episode ends over ``steps`` random steps."""
    import hashlib

    _, fast = pair(env_id)
    rng = np.random.default_rng(3)
    digest = hashlib.sha256()
    observation, _ = fast.reset(seed=5)
    digest.update(observation.tobytes())
    for _ in range(steps):
        action = rng.uniform(-1, 1, fast.action_space.shape).astype(np.float32)
        observation, reward, terminated, _, _ = fast.step(action)
        digest.update(observation.tobytes() + np.float64(reward).tobytes() + bytes([terminated]))
        if terminated:
            observation, _ = fast.reset(seed=int(rng.integers(2**31)))
            digest.update(observation.tobytes())
    fast.close()
    return digest.hexdigest()


# numpy's and OpenBLAS's choices of code that a CPU without AVX-512, or without AVX2, makes
CPU_CHOICES = {
    "as this CPU": {},
    "no AVX-512 in numpy": {"NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR"},
    "no AVX2 in numpy": {"NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"},
    "OpenBLAS without FMA": {"OPENBLAS_CORETYPE": "Prescott"},
    "OpenBLAS for AVX2": {"OPENBLAS_CORETYPE": "Haswell"},
    "OpenBLAS for AVX-512": {"OPENBLAS_CORETYPE": "SkylakeX"},
}


@pytest.mark.parametrize("env_id", ["AntBulletEnv-v0", "AntAsymLeftBulletEnv-v0"])
def test_the_fast_class_gives_the_same_bits_whatever_code_numpy_and_openblas_choose(env_id):
    """The fast class's own arithmetic does not depend on the CPU: the same episodes whichever loops numpy
    dispatches to and whichever kernels OpenBLAS takes (each a choice some CPU makes), in child processes."""
    flags = cpu_flags()
    usable = {name: env for name, env in CPU_CHOICES.items()
              if not ("Haswell" in env.values() and not {"avx2", "fma"} <= flags)
              and not ("SkylakeX" in env.values() and "avx512f" not in flags)}
    code = ("import sys; from tests.test_bullet_locomotion import episode_digest; "
            "print(episode_digest(sys.argv[1], 400))")
    digests = {}
    for name, env in usable.items():
        done = subprocess.run([sys.executable, "-c", code, env_id], cwd=ROOT, env={**os.environ, **env},
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-3000:]
        digests[name] = done.stdout.strip().splitlines()[-1]
    assert len(usable) >= 4 and len(set(digests.values())) == 1, digests
