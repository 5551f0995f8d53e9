"""The damaged quadrupeds of Najarro & Risi (2020), registered as Gymnasium environments.

The paper trains one network on the standard ant and on an ant whose right front lower leg is a
quarter of its length, then walks it on a third body it never saw, with the left front lower leg
shortened instead (docs/original.md, "The damaged ants"). The original repository shipped the two MJCF files and left
their registration, and the averaging over bodies, to the user.

Each damage is one ``fromto`` attribute (0.4 -> 0.1 along both axes: the lower leg shrinks from
0.566 m to 0.141 m). The walk target is at +x, so leg 1 (``left_ankle_geom``) is the front-left
leg and leg 4 (``fourth_ankle_geom``, in a body misleadingly named ``right_back_foot``) the
front-right one.

    id                          model                                     file
    AntAsymLeftBulletEnv-v0     pybullet_data/mjcf/ant.xml, left damaged  damaged_bullet_morphologies/
    AntAsymRightBulletEnv-v0    same, right damaged                       damaged_bullet_morphologies/
    AntAsymLeft-v5              gymnasium mujoco/assets/ant.xml, left     envs/assets/
    AntAsymRight-v5             same, right                               envs/assets/

The MuJoCo files edit Gymnasium's own ``ant.xml``: pyBullet's has no free root joint and no floor,
so Ant-v5 would weld its torso to the world. The pyBullet environments
subclass ``AntBulletEnv``, so they get the whole pyBullet-ant recipe (burn-in, progress reward,
early stop, tanh output) from ``envs.recipes`` by class, not by name.

``python -c "import envs.damaged; envs.damaged.write_morphologies()"`` regenerates the four files
from the installed pybullet and gymnasium models.
"""

from __future__ import annotations

import functools
import importlib.util
from pathlib import Path

import gymnasium as gym

ROOT = Path(__file__).resolve().parent.parent
BULLET_DIR = ROOT / "damaged_bullet_morphologies"
MUJOCO_DIR = Path(__file__).resolve().parent / "assets"

# side -> (geom, standard fromto, damaged fromto), as in the original ant_asym_*.xml files
DAMAGE = {
    "left": ("left_ankle_geom", "0.0 0.0 0.0 0.4 0.4 0.0", "0.0 0.0 0.0 0.1 0.1 0.0"),
    "right": ("fourth_ankle_geom", "0.0 0.0 0.0 0.4 -0.4 0.0", "0.0 0.0 0.0 0.1 -0.1 0.0"),
}
BULLET_IDS = {"AntAsymLeftBulletEnv-v0": "left", "AntAsymRightBulletEnv-v0": "right"}
MUJOCO_IDS = {"AntAsymLeft-v5": "left", "AntAsymRight-v5": "right"}
MAX_EPISODE_STEPS = 1000  # as AntBulletEnv-v0 and Ant-v5


def bullet_xml(side: str) -> Path:
    return BULLET_DIR / f"ant_asym_{side}.xml"


def mujoco_xml(side: str) -> Path:
    return MUJOCO_DIR / f"ant_asym_{side}.xml"


def standard_bullet_xml() -> Path:
    import pybullet_data

    return Path(pybullet_data.getDataPath(), "mjcf", "ant.xml")


def standard_mujoco_xml() -> Path:
    import gymnasium.envs.mujoco

    return Path(gymnasium.envs.mujoco.__file__).parent / "assets" / "ant.xml"


def damage_ant_xml(text: str, side: str) -> str:
    """``text`` (an ant MJCF file) with one lower leg shortened; every other byte unchanged."""
    if side not in DAMAGE:
        raise ValueError(f"unknown damaged side {side!r}; valid: {', '.join(DAMAGE)}")
    geom, standard, damaged = DAMAGE[side]
    old = f'fromto="{standard}" name="{geom}"'
    if text.count(old) != 1:
        raise ValueError(f"expected exactly one {old!r} in the ant model, found {text.count(old)}")
    return text.replace(old, f'fromto="{damaged}" name="{geom}"')


@functools.cache
def damaged_bullet_ant_class(stock: bool = False) -> type:
    """Built on first use, so that pyBullet stays optional for this module; on the batched ant of
    ``envs.bullet_locomotion`` unless ``stock`` (pyBullet's own, to check a result against)."""
    from pybullet_envs_gymnasium.gym_locomotion_envs import AntBulletEnv

    from envs.bullet_locomotion import fast_class

    class DamagedAntBulletEnv(AntBulletEnv if stock else fast_class(AntBulletEnv)):
        """``AntBulletEnv`` whose robot loads another MJCF file.

        pyBullet joins ``model_xml`` to its data folder with ``os.path.join``, which keeps an
        absolute path as it is; the model is loaded at the first reset, so setting it here works.
        """

        def __init__(self, xml_path: str, render_mode: str | None = None):
            super().__init__(render_mode=render_mode)
            self.robot.model_xml = str(xml_path)

    return DamagedAntBulletEnv


def make_damaged_bullet_ant(xml_path: str, render_mode: str | None = None) -> gym.Env:
    """Entry point of the damaged pyBullet ants."""
    return damaged_bullet_ant_class()(xml_path, render_mode=render_mode)


def register() -> None:
    """Register the damaged ants (idempotent); the pyBullet ones only if pyBullet is installed."""
    ant_v5 = gym.spec("Ant-v5")
    for env_id, side in MUJOCO_IDS.items():
        if env_id not in gym.registry:
            gym.register(env_id, entry_point=ant_v5.entry_point, max_episode_steps=MAX_EPISODE_STEPS,
                         kwargs={"xml_file": str(mujoco_xml(side))})
    if importlib.util.find_spec("pybullet_envs_gymnasium") is None:
        return
    for env_id, side in BULLET_IDS.items():
        if env_id not in gym.registry:
            gym.register(env_id, entry_point=make_damaged_bullet_ant, max_episode_steps=MAX_EPISODE_STEPS,
                         kwargs={"xml_path": str(bullet_xml(side))})


def write_morphologies() -> list[Path]:
    """(Re)write the four damaged files from the installed pybullet_data and gymnasium models."""
    written = []
    for side in DAMAGE:
        for source, target in ((standard_bullet_xml(), bullet_xml(side)), (standard_mujoco_xml(), mujoco_xml(side))):
            target.parent.mkdir(parents=True, exist_ok=True)
            # bytes in, bytes out: keep the packaged file's line endings and encoding exactly
            target.write_bytes(damage_ant_xml(source.read_bytes().decode("utf-8"), side).encode("utf-8"))
            written.append(target)
    return written


register()
