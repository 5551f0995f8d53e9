"""The damaged ants of Najarro & Risi (2020) (envs/damaged.py, docs/original.md, "The damaged ants") and fitness over
several bodies.

- each damaged file is the packaged model (pyBullet's pybullet_data/mjcf/ant.xml, Gymnasium's
  mujoco/assets/ant.xml) with exactly the one ``fromto`` line of docs/original.md, "The damaged ants" changed;
- the registered ids make, reset and step, and the pyBullet ones get the whole pyBullet-ant recipe;
- the damaged foot really is shorter once loaded: pyBullet ``getAABB`` (``getCollisionShapeData``
  segfaults on these MJCF links in pyBullet 3.2.7) and the MuJoCo model's capsule size;
- a problem over several environments evaluates each exactly as a problem over that one alone, so
  the fitness of the paper's protocol is the mean of the single-body fitnesses (on two bodies that
  score differently, so that each must have run).
"""

from pathlib import Path
from xml.etree import ElementTree

import gymnasium as gym
import numpy as np
import pybullet_data
import pytest

import envs
from envs import ProblemSpec, damaged, recipes
from es.files import read_metrics
from policies import PolicySettings

FEET = ("front_left_foot", "right_back_foot")  # bodies of left_ankle_geom and fourth_ankle_geom
SOURCES = {"bullet": (damaged.standard_bullet_xml, damaged.bullet_xml),
           "mujoco": (damaged.standard_mujoco_xml, damaged.mujoco_xml)}


@pytest.mark.parametrize("engine", SOURCES)
@pytest.mark.parametrize("side", ["left", "right"])
def test_each_file_changes_one_line_of_the_packaged_ant(engine, side):
    standard_path, damaged_path = SOURCES[engine]
    standard = standard_path().read_bytes()
    changed = damaged_path(side).read_bytes()
    assert changed == damaged.damage_ant_xml(standard.decode(), side).encode()
    pairs = list(zip(standard.splitlines(keepends=True), changed.splitlines(keepends=True), strict=True))
    different = [(old, new) for old, new in pairs if old != new]
    geom, before, after = damaged.DAMAGE[side]
    assert len(different) == 1
    old, new = different[0]
    assert f'fromto="{before}" name="{geom}"'.encode() in old
    assert new == old.replace(before.encode(), after.encode())


def test_bullet_files_match_the_originals_size():
    # the original repository's files are 4,233 bytes each, as pyBullet 3.2.7's ant.xml (docs/original.md,
    # "The damaged ants")
    assert [damaged.bullet_xml(side).stat().st_size for side in ("left", "right")] == [4233, 4233]


@pytest.mark.parametrize("env_id, standard_id", [
    ("AntAsymLeftBulletEnv-v0", "AntBulletEnv-v0"), ("AntAsymRightBulletEnv-v0", "AntBulletEnv-v0"),
    ("AntAsymLeft-v5", "Ant-v5"), ("AntAsymRight-v5", "Ant-v5")])
def test_registered_ids_make_reset_and_step(env_id, standard_id):
    assert envs.resolve_env_id(env_id) == env_id
    env, recipe = envs.make_env(env_id)
    try:
        observation, _ = env.reset(seed=3)
        observation, reward, terminated, truncated, _ = env.step(np.zeros(env.action_space.shape))
        standard = gym.spec(standard_id)
        assert env.spec.max_episode_steps == standard.max_episode_steps == 1000
        reference = gym.make(standard_id)
        assert observation.shape == reference.observation_space.shape
        reference.close()
        assert np.isfinite(reward) and not truncated
        expected = recipes.PYBULLET_ANT if "Bullet" in env_id else recipes.GYMNASIUM
        assert recipe is expected  # burn-in, progress reward, early stop, tanh output for pyBullet
    finally:
        env.close()


def bullet_foot_spans(env_id: str) -> dict[str, float]:
    """x extent of each damaged-side foot's axis-aligned bounding box right after a reset."""
    env = gym.make(env_id)
    try:
        env.reset(seed=0)
        robot, client = env.unwrapped.robot, env.unwrapped._p
        spans = {}
        for foot in FEET:
            part = robot.parts[foot]
            low, high = client.getAABB(part.bodies[part.bodyIndex], part.bodyPartIndex)
            spans[foot] = high[0] - low[0]
        return spans
    finally:
        env.close()


def test_bullet_damaged_foot_is_shorter():
    standard = bullet_foot_spans("AntBulletEnv-v0")
    left = bullet_foot_spans("AntAsymLeftBulletEnv-v0")
    right = bullet_foot_spans("AntAsymRightBulletEnv-v0")
    # lower leg 0.4 -> 0.1 along x, capsule radius 0.08 at both ends: the span shrinks by about 0.3
    assert standard["front_left_foot"] - left["front_left_foot"] == pytest.approx(0.3, abs=0.02)
    assert standard["right_back_foot"] - right["right_back_foot"] == pytest.approx(0.3, abs=0.02)
    assert left["right_back_foot"] == pytest.approx(standard["right_back_foot"], abs=1e-6)
    assert right["front_left_foot"] == pytest.approx(standard["front_left_foot"], abs=1e-6)


def test_mujoco_damaged_foot_is_shorter():
    import mujoco

    def half_lengths(env_id):
        model = gym.make(env_id).unwrapped.model
        ids = {geom: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, geom)
               for geom in ("left_ankle_geom", "fourth_ankle_geom")}
        assert model.nq == 15  # Gymnasium's ant keeps its free root joint
        return {geom: model.geom_size[index][1] for geom, index in ids.items()}

    full, quarter = np.hypot(0.4, 0.4) / 2, np.hypot(0.1, 0.1) / 2  # capsule half-lengths
    assert half_lengths("Ant-v5") == pytest.approx({"left_ankle_geom": full, "fourth_ankle_geom": full})
    assert half_lengths("AntAsymLeft-v5") == pytest.approx({"left_ankle_geom": quarter, "fourth_ankle_geom": full})
    assert half_lengths("AntAsymRight-v5") == pytest.approx({"left_ankle_geom": full, "fourth_ankle_geom": quarter})


def test_fitness_over_two_bodies_is_the_mean_of_each_alone():
    pair = ("AntBulletEnv-v0", "AntAsymRightBulletEnv-v0")
    both = ProblemSpec(pair, PolicySettings("hebbian")).build()
    try:
        params = both.policy.initial_params(np.random.default_rng(4))
        together = [both.evaluate(params, index, seed=1).total_return for index in range(2)]
    finally:
        both.close()
    alone = []
    for env_id in pair:
        problem = ProblemSpec((env_id,), PolicySettings("hebbian")).build()
        try:
            alone.append(problem.evaluate(params, 0, seed=1).total_return)
        finally:
            problem.close()
    assert together == alone
    assert together[0] != together[1]  # the damaged body really behaves differently


def test_training_fitness_over_two_bodies_is_the_mean_of_each(tmp_path):
    """Through the real training front end: same seed, one generation, each body alone and both. The two
    bodies give different fitness, so a run that evaluated only one of them, or one twice, would fail."""
    import train_static

    def first_row(environment: str) -> dict:
        folder = tmp_path / environment.replace(",", "+")
        argv = ["--environment", environment, "--generations", "1", "--popsize", "4", "--seed", "5",
                "--max_episode_steps", "40", "--threads", "1", "--folder", str(folder)]
        assert train_static.main(argv) == 0
        (run_dir,) = Path(folder).iterdir()
        return read_metrics(run_dir / "metrics.csv")[0]

    both, first, second = (first_row(text) for text in ("Ant-v5,AntAsymLeft-v5", "Ant-v5", "AntAsymLeft-v5"))
    for column in ("fitness_mean", "center_return"):
        assert float(first[column]) != float(second[column])  # so that the mean tells them apart
        assert float(both[column]) == pytest.approx((float(first[column]) + float(second[column])) / 2)
    assert int(both["env_steps"]) == int(first["env_steps"]) + int(second["env_steps"])  # every episode of each


def test_envs_of_different_sizes_are_one_line_and_exit_2(tmp_path, capsys):
    import train_static

    argv = ["--environment", "AntBulletEnv-v0,CartPole-v1", "--generations", "1", "--popsize", "2",
            "--threads", "1", "--folder", str(tmp_path / "runs")]
    assert train_static.main(argv) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1
    assert "CartPole-v1" in error and "share observation and action sizes" in error
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize("env_id", ["AntBulletEnv-v0", "AntAsymRightBulletEnv-v0", "AntAsymLeftBulletEnv-v0"])
def test_a_resting_bullet_ant_lies_below_the_alive_height_and_its_episode_ends_at_step_202(env_id):
    """Why the campaign's ant episodes all end near step 242 (experiments/README.md, "The ant, static, seed 1"):
    with its motors at rest the ant settles on its torso, below the 0.26 m under which pyBullet ends the episode,
    within 20 steps; the original's loop ignores that end for the first 201 policy steps and stops at the next
    check, so a network that does not lift the torso gets 40 burn-in steps and 202 policy steps."""
    env = gym.make(env_id)
    try:
        env.reset(seed=3)
        robot = env.unwrapped.robot
        ended = [env.step(np.zeros(8, dtype=np.float32))[2] for _ in range(20)]
        assert ended[-1] and robot.body_real_xyz[2] < 0.26
        # it lies on its torso: a sphere of radius 0.25 in the body's file (the same in pyBullet 2.6.6, the
        # version the original pins), so the height is the file's, not the engine's
        side = {"AntBulletEnv-v0": None, "AntAsymRightBulletEnv-v0": "right", "AntAsymLeftBulletEnv-v0": "left"}[env_id]
        xml = damaged.bullet_xml(side) if side else Path(pybullet_data.getDataPath()) / "mjcf" / "ant.xml"
        torso = ElementTree.parse(xml).find(".//geom[@name='torso_geom']")
        assert (torso.get("type"), torso.get("size")) == ("sphere", "0.25")
        assert robot.body_real_xyz[2] == pytest.approx(0.25, abs=0.005)
    finally:
        env.close()
    problem = ProblemSpec((env_id,), PolicySettings("static")).build()
    try:
        still = np.zeros(problem.policy.num_params, dtype=np.float32)  # tanh(0): every action 0, the motors at rest
        episode = envs.rollout(problem.envs[0], problem.policy, still, seed=3)
    finally:
        problem.close()
    assert episode.steps == recipes.PYBULLET_ANT.burn_in + 202
