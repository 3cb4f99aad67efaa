"""Build the MuJoCo model of a task: robot + floor (+ tray, cup, payload), with ``MjSpec``.

The robot and scene files of ``assets/mjcf`` hold the robot, the floor, lights and the goal
marker. A tray task also needs a tray fixed to the end effector, level at the reset pose, and a
free cup on it whose friction against the tray is set on an explicit contact pair (MuJoCo
otherwise combines two geoms' friction by taking the larger, so a cup setting alone would change
nothing). Those depend on the task's parameters, so they are added here.

Sizes and masses (DESIGN 5, from the authors' demo, reference/krang_facts.md 5.3): tray
0.30 x 0.20 m, 0.2 kg; cup radius 0.031 m, height 0.08 m, 0.05 kg; tray-cup friction 0.3.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from wip_gym.assets import mjcf_path
from wip_gym.robot_model import RobotModel
from wip_gym.robots import robot_spec

TRAY_HALF_SIZE = (0.15, 0.10, 0.005)  # 0.30 x 0.20 m plate, 1 cm thick
TRAY_MASS = 0.2
CUP_RADIUS = 0.031
CUP_HALF_HEIGHT = 0.04
CUP_MASS = 0.05
PAYLOAD_RADIUS = 0.04  # a 8 cm sphere in the hand, for its inertia and its picture


@dataclass(frozen=True)
class SceneOptions:
    """What to build.

    Attributes:
        robot: ``wip``, ``planar7`` or ``krang``.
        tray: add a tray fixed to the end effector (level at the reset pose).
        cup: add a free cup resting on the tray (needs ``tray``).
        cup_friction: tray-cup friction coefficient (set on the explicit contact pair).
        payload_mass: mass (kg) of a payload body welded to the hand (``ee`` site).
        wheel_torque_limit: each wheel motor's torque limit (N m); 150 as in the authors'
            simulation, 63.6 for Krang's hardware (reference/krang_facts.md 1.5).
    """

    robot: str
    tray: bool = False
    cup: bool = False
    cup_friction: float = 0.3
    payload_mass: float = 0.0
    wheel_torque_limit: float = 150.0

    def __post_init__(self) -> None:
        spec = robot_spec(self.robot)
        if (self.tray or self.cup) and not spec.tray_capable:
            raise ValueError(f"robot {self.robot!r} has no end effector for a tray")
        if self.cup and not self.tray:
            raise ValueError("a cup needs a tray")
        for name in ("cup_friction", "payload_mass", "wheel_torque_limit"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        if self.wheel_torque_limit == 0:
            raise ValueError("wheel_torque_limit must be positive")


def reset_qpos(model: mujoco.MjModel, robot: RobotModel | None = None) -> np.ndarray:
    """The robot's noise-free reset pose: the ``home`` keyframe (or all zeros) at the origin,
    heading 0, with the base pitched about the axle so the body CoM is exactly above it."""
    robot = robot or RobotModel(model)
    lay = robot.layout
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "home")
    qpos = model.key_qpos[key][: lay.nq].copy() if key >= 0 else model.qpos0[: lay.nq].copy()
    robot.update(qpos, np.zeros(lay.nv), dynamics=False)
    q = robot.q.copy()
    q[lay.index_x] = 0.0
    if lay.index_psi is not None:
        q[lay.index_psi] = 0.0
    # the body rotates rigidly about the axle with q1: subtracting theta puts the CoM above it
    q[lay.index_q1] -= robot.theta
    return robot.full_state(q, np.zeros(lay.n_min))[0]


def _add_tray(spec: mujoco.MjSpec, quat: np.ndarray) -> None:
    mount = spec.site("tray_mount")
    tray = mount.parent.add_body(name="tray", pos=mount.pos, quat=quat)
    tray.add_geom(
        name="tray",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=TRAY_HALF_SIZE,
        pos=[0.0, 0.0, TRAY_HALF_SIZE[2]],
        mass=TRAY_MASS,
        contype=0,
        conaffinity=0,
        material="tray",
    )
    tray.add_site(name="tray_top", pos=[0.0, 0.0, 2 * TRAY_HALF_SIZE[2]], size=[0.01] * 3)


def _add_cup(spec: mujoco.MjSpec, friction: float) -> None:
    cup = spec.worldbody.add_body(name="cup", pos=[0.0, 0.0, 1.0])
    cup.add_freejoint(name="cup")
    cup.add_geom(
        name="cup",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[CUP_RADIUS, CUP_HALF_HEIGHT, 0.0],
        mass=CUP_MASS,
        contype=4,  # meets the floor (conaffinity 1), not the robot (contype 2)
        conaffinity=1,
        material="cup",
    )
    spec.add_pair(
        name="tray_cup",
        geomname1="tray",
        geomname2="cup",
        condim=3,
        friction=[friction, friction, 0.005, 0.0001, 0.0001],
    )


def _add_payload(spec: mujoco.MjSpec, mass: float) -> None:
    ee = spec.site("ee")
    inertia = 0.4 * mass * PAYLOAD_RADIUS**2
    payload = ee.parent.add_body(
        name="payload",
        pos=ee.pos,
        mass=mass,
        inertia=[inertia] * 3,
        explicitinertial=True,
    )
    payload.add_geom(
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=[PAYLOAD_RADIUS, 0, 0],
        contype=0,
        conaffinity=0,
        mass=0.0,
        rgba=[0.4, 0.4, 0.4, 0.6 if mass > 0 else 0.0],
    )


def build_spec(options: SceneOptions) -> mujoco.MjSpec:
    """The ``MjSpec`` of the task (see :class:`SceneOptions`)."""
    spec_of_robot = robot_spec(options.robot)
    tray_quat = np.array([1.0, 0.0, 0.0, 0.0])
    # the tray must be level at the reset pose, which its own mass shifts slightly: iterate
    for _ in range(3 if options.tray else 1):
        spec = mujoco.MjSpec.from_file(str(mjcf_path(spec_of_robot.scene_file)))
        for name in ("wheel_left", "wheel_right"):
            spec.actuator(name).ctrlrange = [
                -options.wheel_torque_limit,
                options.wheel_torque_limit,
            ]
        if spec_of_robot.tray_capable:
            _add_payload(spec, options.payload_mass)
        if options.tray:
            _add_tray(spec, tray_quat)
        if not options.tray:
            break
        model = spec.compile()
        data = mujoco.MjData(model)
        pose = reset_qpos(model)
        data.qpos[: len(pose)] = pose
        mujoco.mj_kinematics(model, data)
        mount_body = model.site_bodyid[
            mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "tray_mount")
        ]
        world_from_body = np.zeros(4)
        mujoco.mju_mat2Quat(world_from_body, data.xmat[mount_body])
        tray_quat = np.zeros(4)
        mujoco.mju_negQuat(tray_quat, world_from_body)  # body_from_world: level, heading 0
    if options.cup:
        _add_cup(spec, options.cup_friction)
    return spec


def build_model(options: SceneOptions) -> mujoco.MjModel:
    """Compile the task's model."""
    return build_spec(options).compile()
