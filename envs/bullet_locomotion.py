"""pyBullet's walkers (ant, half-cheetah, hopper, walker) stepped faster, with the same numbers.

``pybullet_envs_gymnasium`` computes each step's observation and reward in Python, one physics
query per joint, per body part and per foot: the ant calls pyBullet 46 times a step besides stepping
its physics, and those calls cost more than the physics itself. ``FastWalker`` asks the same
questions in batches (the torques, the joint states, the links' states, each base's pose, the
torso's velocity, the contacts: seven calls for the ant) and keeps every line of arithmetic of
``WalkerBase.calc_state``, ``WalkerBase.apply_action`` and ``WalkerBaseBulletEnv.step`` in the same
order on the same dtypes, so observations, rewards and episode ends are pyBullet's own
(``tests/test_bullet_locomotion.py`` steps both side by side).

Its own arithmetic is the same whatever code the CPU takes. pyBullet's ``calc_state`` leaves four of its operations to
code that numpy and OpenBLAS choose by the CPU they run on: ``np.arctan2`` (numpy's AVX-512 code
differs from the C library's in the last bit), ``np.sin`` and ``np.cos`` (the C library's on every CPU
measured, numpy's own where it has one), ``np.linalg.norm`` of two numbers and ``np.dot`` of a 3 × 3
matrix with a 3-vector (OpenBLAS: a fused multiply-add or not, by kernel). Here these are the C
library's scalar ``math.atan2``, ``math.sin`` and ``math.cos``, a plain ``sqrt(dy² + dx²)``, and each
row of the rotation as ``fma(r0, s0, r1 s1) + r2 s2`` with an exactly emulated fused multiply-add:
the numbers pyBullet's class gives on an x86-64 CPU with AVX2 and FMA but without AVX-512 (OpenBLAS's
Haswell and Zen kernels), whatever CPU this class runs on, given the same C library's code for its scalar
functions (glibc picks them by the CPU's FMA and AVX2, as it does for the physics). On a CPU with AVX-512, or
one without AVX2, pyBullet's own class gives other last bits, and its episodes part from these
(docs/reproducibility.md).

The registered ``*BulletEnv-v0`` walkers make the fast classes; ``envs.bullet_locomotion.STOCK_IDS``
maps each to a ``*BulletStockEnv-v0`` id that makes pyBullet's own class, to check any result
against. A robot that replaces the walker's step (the humanoids apply their own torques), or a scene
whose ground could be one of the robot's own parts, is stepped by pyBullet's code unchanged.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from fractions import Fraction

import gymnasium as gym
import numpy as np
import pybullet
import pybullet_envs_gymnasium.gym_locomotion_envs as locomotion
from pybullet_envs_gymnasium.robot_locomotors import WalkerBase

# the walkers whose robots use WalkerBase's observation and torques; the humanoids override the torques
FAST_IDS = ("AntBulletEnv-v0", "HalfCheetahBulletEnv-v0", "HopperBulletEnv-v0", "Walker2DBulletEnv-v0")
STOCK_IDS = {env_id: env_id.replace("BulletEnv", "BulletStockEnv") for env_id in FAST_IDS}


_SPLIT = 134217729.0  # 2^27 + 1: Veltkamp's split of a double into two halves of 26 bits
_DEKKER = (2.0 ** -450, 2.0 ** 450)  # |a| and |b| in this range: Dekker's product below is exact


def _fused(a: float, b: float, c: float) -> float:
    """a b + c rounded once, as a CPU's fused multiply-add gives it, computed on any CPU: a b as the exact
    sum of two doubles (Dekker 1971), the three added with one rounding (``math.fsum`` is correctly
    rounded); outside Dekker's range, with exact fractions."""
    product = a * b
    if a == 0.0 or b == 0.0:
        return product + c  # an exact product: the instruction's one rounding is the sum's
    low, high = _DEKKER
    if not (low < abs(a) < high and low < abs(b) < high and math.isfinite(c)):
        exact = Fraction(a) * Fraction(b) + Fraction(c) if math.isfinite(product) and math.isfinite(c) else 0
        if exact == 0:
            return product + c  # inf and nan, or a sum of zeros: as the instruction gives them
        if abs(exact) >= 2 ** 1024:
            return math.copysign(math.inf, exact)
        return math.copysign(float(exact), exact)  # (a tiny sum rounds to a zero of its sign)
    a_high = a * _SPLIT - (a * _SPLIT - a)
    b_high = b * _SPLIT - (b * _SPLIT - b)
    a_low, b_low = a - a_high, b - b_high
    error = ((a_high * b_high - product) + a_high * b_low + a_low * b_high) + a_low * b_low
    return product + c if error == 0.0 else math.fsum((product, error, c))


def _rotated(cosine: float, sine: float, speed) -> tuple[float, float, float]:
    """``np.dot(rot_speed, speed)`` of ``WalkerBase.calc_state``, row by row as OpenBLAS's Haswell kernel
    sums a 3-element row: fma(r0, s0, r1 s1) + r2 s2, the last product fused too."""
    rows = ((cosine, -sine, 0), (sine, cosine, 0), (0, 0, 1))
    sx, sy, sz = (float(value) for value in speed)
    return tuple(_fused(r2, sz, _fused(r0, sx, r1 * sy)) for r0, r1, r2 in rows)


@dataclasses.dataclass(frozen=True)
class _Queries:
    """What one step asks pyBullet, worked out once per reset from the robot's parts and joints."""
    joint_body: int
    joint_indices: list[int]
    lower: np.ndarray  # joint limits, as pyBullet's Joint holds them: the lower and upper - lower
    span: np.ndarray
    power: np.ndarray  # robot.power * joint.power_coef, per joint (float64, the stock product)
    part_links: list[tuple[int, int]]  # (body, link) of every part, in the parts dict's order
    torso: tuple[int, int]  # (body, link) of robot.robot_body
    link_calls: dict[int, list[int]]  # body -> its links among the parts, for one getLinkStates each
    base_bodies: list[int]  # bodies whose base is a part (or the torso), one getBasePositionAndOrientation each
    feet: list[tuple[int, int]]  # (body, link) of each foot


def _queries(robot) -> _Queries | None:
    """The batched plan for ``robot``, or None where the batched step would not be exact."""
    joints = robot.ordered_joints
    bodies = {joint.bodies[joint.bodyIndex] for joint in joints}
    if len(bodies) != 1:
        return None

    def where(part) -> tuple[int, int]:
        return part.bodies[part.bodyIndex], part.bodyPartIndex

    part_links = [where(part) for part in robot.parts.values()]
    torso = where(robot.robot_body)
    link_calls: dict[int, list[int]] = {}
    for body, link in dict.fromkeys([*part_links, torso]):
        if link != -1:
            link_calls.setdefault(body, []).append(link)
    base_bodies = list(dict.fromkeys(body for body, link in [*part_links, torso] if link == -1))
    return _Queries(
        joint_body=bodies.pop(), joint_indices=[joint.jointIndex for joint in joints],
        lower=np.array([joint.lowerLimit for joint in joints]),
        span=np.array([joint.upperLimit - joint.lowerLimit for joint in joints]),
        power=np.array([robot.power * joint.power_coef for joint in joints]),
        part_links=part_links, torso=torso, link_calls=link_calls, base_bodies=base_bodies,
        feet=[where(foot) for foot in robot.feet])


@functools.cache
def fast_class(stock: type) -> type:
    """``stock`` (a ``WalkerBaseBulletEnv`` subclass) with the batched step."""
    namespace = {"__module__": __name__, "__qualname__": stock.__name__,
                 "__doc__": f"pyBullet's {stock.__name__}, its step batched (envs.bullet_locomotion)."}
    return type(stock.__name__, (FastWalker, stock), namespace)


class FastWalker:
    """Mixin before a ``WalkerBaseBulletEnv`` subclass: its ``step`` with batched queries."""

    _plan: _Queries | None = None

    def reset(self, seed=None, options=None):
        robot = self.robot
        if self._same_code():  # the reset's state (and so its potential) with this class's arithmetic
            robot.calc_state = lambda: self._reset_state(robot)
        try:
            observation, info = super().reset(seed=seed, options=options)
        finally:
            robot.__dict__.pop("calc_state", None)
        self._plan = _queries(robot) if self._same_code() and self._ground_apart() else None
        return observation, info

    def _reset_state(self, robot) -> np.ndarray:
        """``robot.calc_state()`` inside pyBullet's reset, with the robot's parts as they are then (the first
        reset's lack the floor, which later states average in, as pyBullet's own class does)."""
        plan = _queries(robot)
        return WalkerBase.calc_state(robot) if plan is None else self._calc_state(self._p._client, plan)

    def _same_code(self) -> bool:
        robot = type(self.robot)
        return (robot.calc_state is WalkerBase.calc_state and robot.apply_action is WalkerBase.apply_action
                and type(self).step is FastWalker.step
                and super().step.__func__ is locomotion.WalkerBaseBulletEnv.step)

    def _ground_apart(self) -> bool:
        """A foot's contacts are read for the whole body at once: exact while the ground is another body's
        base (and the scene holds one robot)."""
        feet_bodies = {foot.bodies[foot.bodyIndex] for foot in self.robot.feet}
        ground_apart = all(link == -1 and body not in feet_bodies for body, link in self.ground_ids)
        return ground_apart and not self.scene.multiplayer

    def step(self, a):
        if self._plan is None:
            return super().step(a)
        client = self._p._client
        plan, robot = self._plan, self.robot
        # WalkerBase.apply_action: the same float64 torques, one call
        assert np.isfinite(a).all()
        action = np.asarray(a)
        torques = plan.power * np.clip(action[:len(plan.joint_indices)], -1, +1).astype(np.float64)
        pybullet.setJointMotorControlArray(plan.joint_body, plan.joint_indices, pybullet.TORQUE_CONTROL,
                                           forces=torques.tolist(), physicsClientId=client)
        self.scene.global_step()

        state = self._calc_state(client, plan)
        self._alive = float(robot.alive_bonus(state[0] + robot.initial_z, robot.body_rpy[1]))
        done = self._isDone()
        if not np.isfinite(state).all():
            print("~INF~", state)
            done = True

        potential_old = self.potential
        self.potential = robot.calc_potential()
        progress = float(self.potential - potential_old)

        contacts = self._contacts(client)
        for i, foot in enumerate(plan.feet):
            robot.feet_contact[i] = 1.0 if self.ground_ids & contacts.get(foot, set()) else 0.0
        feet_collision_cost = 0.0

        electricity_cost = self.electricity_cost * float(np.abs(a * robot.joint_speeds).mean())
        electricity_cost += self.stall_torque_cost * float(np.square(a).mean())
        joints_at_limit_cost = float(self.joints_at_limit_cost * robot.joints_at_limit)

        self.rewards = [self._alive, progress, electricity_cost, joints_at_limit_cost, feet_collision_cost]
        self.HUD(state, a, done)
        self.reward += sum(self.rewards)
        return state, sum(self.rewards), bool(done), False, {}

    def _contacts(self, client: int) -> dict[tuple[int, int], set[tuple[int, int]]]:
        """(body, link) of each foot -> the (body, link) pairs it touches, as ``BodyPart.contact_list``
        reports them (only another body's base counts: pyBullet's filter on link B is -1)."""
        touching: dict[tuple[int, int], set[tuple[int, int]]] = {}
        for body in dict.fromkeys(body for body, _ in self._plan.feet):
            for point in pybullet.getContactPoints(bodyA=body, physicsClientId=client):
                touching.setdefault((body, point[3]), set()).add((point[2], point[4]))
        return touching

    def _calc_state(self, client: int, plan: _Queries) -> np.ndarray:
        """``WalkerBase.calc_state``, every number computed as there, from batched queries."""
        robot = self.robot
        joints = pybullet.getJointStates(plan.joint_body, plan.joint_indices, physicsClientId=client)
        position = np.array([joint[0] for joint in joints])
        velocity = np.array([joint[1] for joint in joints])
        scaled = np.empty((len(joints), 2))
        scaled[:, 0] = 2 * (position - plan.lower) / plan.span - 1.0
        scaled[:, 1] = 0.1 * velocity
        j = scaled.astype(np.float32).flatten()
        robot.joint_speeds = j[1::2]
        robot.joints_at_limit = np.count_nonzero(np.abs(j[0::2]) > 0.99)

        pose = {}
        for body, links in plan.link_calls.items():
            for link, state in zip(links, pybullet.getLinkStates(body, links, physicsClientId=client)):
                pose[body, link] = state[0], state[1]
        for body in plan.base_bodies:
            pose[body, -1] = pybullet.getBasePositionAndOrientation(body, physicsClientId=client)
        parts_xyz = np.array([pose[part][0] for part in plan.part_links]).flatten()
        torso_position, torso_orientation = pose[plan.torso]
        body_xyz = np.array(torso_position)

        robot.body_xyz = (parts_xyz[0::3].mean(), parts_xyz[1::3].mean(), body_xyz[2])
        robot.body_real_xyz = body_xyz
        robot.body_rpy = pybullet.getEulerFromQuaternion(np.array(torso_orientation))
        z = robot.body_xyz[2]
        if robot.initial_z is None:
            robot.initial_z = z
        r, p, yaw = robot.body_rpy
        # the module's docstring: each operation as pyBullet's class gives it on an AVX2 CPU, whatever the CPU
        dy = float(robot.walk_target_y - robot.body_xyz[1])
        dx = float(robot.walk_target_x - robot.body_xyz[0])
        robot.walk_target_theta = np.float64(math.atan2(dy, dx))
        robot.walk_target_dist = np.float64(math.sqrt(dy * dy + dx * dx))
        angle_to_target = robot.walk_target_theta - yaw
        vx, vy, vz = _rotated(math.cos(-yaw), math.sin(-yaw), robot.robot_body.speed())
        more = np.array([z - robot.initial_z, math.sin(angle_to_target), math.cos(angle_to_target),
                         0.3 * vx, 0.3 * vy, 0.3 * vz, r, p], dtype=np.float32)
        return np.clip(np.concatenate([more, j, robot.feet_contact]), -5, +5)


def register() -> None:
    """Point each walker's id at its fast class and add its stock id (idempotent; needs pyBullet)."""
    for env_id, stock_id in STOCK_IDS.items():
        spec = gym.registry.get(env_id)
        if spec is None or stock_id in gym.registry:
            continue
        gym.registry[stock_id] = dataclasses.replace(spec, id=stock_id)
        name = spec.entry_point.rpartition(":")[2]
        gym.registry[env_id] = dataclasses.replace(spec, entry_point=f"{__name__}:{name}")


def __getattr__(name: str) -> type:
    """``envs.bullet_locomotion.AntBulletEnv`` and its kin: the fast classes, by the stock names, so
    that entry points are strings and the classes are found by module and name."""
    stock = getattr(locomotion, name, None)
    if not (isinstance(stock, type) and issubclass(stock, locomotion.WalkerBaseBulletEnv)):
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return fast_class(stock)
