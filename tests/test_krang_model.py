"""Checks of assets/mjcf/krang.xml against the KrangOld numbers of docs/AUTHORS_CONFIG.md.

The model drops the kinect (0.705 kg) and the four gripper plates (0.0001 kg each), so the
derived facts (which include the kinect) are matched within what the kinect explains; a copy of
the model with the kinect put back (via ``mujoco.MjSpec``) must reproduce them to rounding.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
from conftest import home_data as home

SCENE = Path(__file__).parents[1] / "assets/mjcf/scene_krang.xml"

ARM_JOINTS = [f"{side}_j{i}" for side in ("left", "right") for i in range(1, 8)]
ACTUATED = ["wheel_left", "wheel_right", "waist", "torso", *ARM_JOINTS]
ARM_TORQUES = [370.0, 370.0, 175.0, 175.0, 40.0, 40.0, 9.5]
TORQUE_LIMITS = [150.0, 150.0, 740.0, 370.0, *ARM_TORQUES, *ARM_TORQUES]

# docs/AUTHORS_CONFIG.md §1.2, §1.6 (derived numbers include the kinect).
FACTS_TOTAL_MASS = 162.863
KINECT_MASS = 0.705
PLATE_MASS = 0.0001
FACTS_BODY_COM_DISTANCE = 0.2921
FACTS_WHOLE_COM_DISTANCE = 0.2754
FACTS_QBASE = -0.923
FACTS_EE_LEFT = np.array([0.1225, 0.2869, 0.4074])
FACTS_EE_RIGHT = np.array([0.1203, -0.2857, 0.4149])
FACTS_TRAY = np.array([0.117, 0.001, 0.714 - 0.264])  # world (base at z 0.264) -> axle frame

HOME_JOINTS = {
    "waist": 1.98558,
    "torso": 0.053232,
    **dict(
        zip(
            ARM_JOINTS,
            [
                -1.36631,
                -0.495357,
                0.969689,
                -1.55801,
                -0.421576,
                -1.27307,
                -1.35663,
                1.2217,
                0.606397,
                -0.91889,
                1.50091,
                0.516969,
                1.31059,
                1.26479,
            ],
            strict=True,
        )
    ),
}


@pytest.fixture(scope="module")
def model(scene_model) -> mujoco.MjModel:
    return scene_model("krang")


def base_pitch(data: mujoco.MjData) -> float:
    """Rotation of ``base`` about +y (positive leans forward), from its world z axis."""
    z_axis = data.body("base").xmat.reshape(3, 3)[:, 2]
    return math.atan2(z_axis[0], z_axis[2])


def in_axle_frame(data: mujoco.MjData, point: np.ndarray) -> np.ndarray:
    """A world point in frame 0: origin at the axle midpoint, rotated by the heading only."""
    x_axis = data.body("base").xmat.reshape(3, 3)[:, 0]
    psi = math.atan2(x_axis[1], x_axis[0])
    c, s = math.cos(psi), math.sin(psi)
    rot0 = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return rot0 @ (point - data.body("base").xpos)


def com(model: mujoco.MjModel, data: mujoco.MjData, wheels: bool = False) -> np.ndarray:
    """CoM of the robot (without the wheels unless ``wheels``) in the axle frame."""
    skip = set() if wheels else {model.body("wheel_left").id, model.body("wheel_right").id}
    root = model.body("base").id
    ids = [b for b in range(model.nbody) if model.body_rootid[b] == root and b not in skip]
    mass = model.body_mass[ids]
    return in_axle_frame(data, (mass[:, None] * data.xipos[ids]).sum(axis=0) / mass.sum())


def with_kinect() -> mujoco.MjModel:
    """The scene with KrangOld's kinect welded to ``torso`` at its initial angle -0.0575697."""
    spec = mujoco.MjSpec.from_file(str(SCENE))
    # JKinect: origin (-0.001, 0.1805, -0.112), rpy (3.1416, 0, 0), axis +x: a rotation about x
    # by 3.1416 - 0.0575697. Link: 0.705 kg, CoM (0, -0.04, -0.028) (inertia is a placeholder).
    angle = 3.1416 - 0.0575697
    quat = [math.cos(angle / 2), math.sin(angle / 2), 0.0, 0.0]
    spec.body("torso").add_body(
        name="kinect",
        pos=[-0.001, 0.1805, -0.112],
        quat=quat,
        mass=KINECT_MASS,
        ipos=[0.0, -0.04, -0.028],
        inertia=[0.01, 0.01, 0.01],
        explicitinertial=True,
    )
    return spec.compile()


def balance(model: mujoco.MjModel, data: mujoco.MjData) -> float:
    """Re-pitch ``base`` about the axle so the body CoM is over it; return the new pitch."""
    c = com(model, data)
    pitch = base_pitch(data) - math.atan2(c[0], c[2])
    data.qpos[3:7] = [math.cos(pitch / 2), 0.0, math.sin(pitch / 2), 0.0]
    mujoco.mj_forward(model, data)
    return pitch


def test_sizes_and_names(model: mujoco.MjModel) -> None:
    """19 DOF after rolling = free base (6) + 2 wheels + 16 body joints; 18 torque motors."""
    assert model.nq == 7 + 2 + 16
    assert model.nv == 6 + 2 + 16 == 24
    joints = [model.joint(j).name for j in range(model.njnt)]
    assert joints == ["root", *ACTUATED]
    assert model.joint("root").type == mujoco.mjtJoint.mjJNT_FREE
    links = [f"{side}_{i}" for side in ("left", "right") for i in range(1, 7)]
    for name in ["base", "spine", "torso", "left_gripper", "right_gripper", *links]:
        assert model.body(name).id > 0
    assert model.body("wheel_left").parentid == model.body("base").id
    assert model.body("wheel_right").parentid == model.body("base").id
    assert model.body("base").parentid == 0


def test_actuators(model: mujoco.MjModel) -> None:
    """One motor per actuated joint, named as it, contract order, torque limits of facts 1.5."""
    assert model.nu == len(ACTUATED) == 18
    for i, (name, limit) in enumerate(zip(ACTUATED, TORQUE_LIMITS, strict=True)):
        act = model.actuator(i)
        assert act.name == name
        assert model.joint(act.trnid[0]).name == name
        assert act.gear[0] == 1.0
        assert model.actuator_ctrllimited[i]
        np.testing.assert_allclose(act.ctrlrange, [-limit, limit])


def test_joint_axes_and_limits(model: mujoco.MjModel) -> None:
    """Wheels: hinge +y unlimited at +-0.34; body joints limited as in KrangOld.urdf."""
    for name, y in (("wheel_left", 0.34), ("wheel_right", -0.34)):
        np.testing.assert_allclose(model.body(name).pos, [0.0, y, 0.0])
        np.testing.assert_allclose(model.joint(name).axis, [0.0, 1.0, 0.0])
        assert not model.jnt_limited[model.joint(name).id]
    limits = {"waist": (0.0, 2.7), "torso": (-0.8, 0.8)}
    for side, j1 in (("left", 3.1416), ("right", 4.7124)):
        for i, lim in enumerate((j1, 2.094, 4.7124, 2.094, 4.7124, 2.094, 4.7124), start=1):
            limits[f"{side}_j{i}"] = (-lim, lim)
    for name, rng in limits.items():
        assert model.jnt_limited[model.joint(name).id]
        np.testing.assert_allclose(model.joint(name).range, rng)
        lo, hi = rng
        assert lo <= HOME_JOINTS[name] <= hi


def test_wheel_geoms(model: mujoco.MjModel) -> None:
    """Wheel collision geoms are spheres of the controllers' radius 0.25 centred on the axle."""
    for name in ("wheel_left", "wheel_right"):
        geom = model.geom(name)
        assert geom.type == mujoco.mjtGeom.mjGEOM_SPHERE
        assert geom.size[0] == pytest.approx(0.25)
        np.testing.assert_allclose(geom.pos, 0.0, atol=1e-12)
        assert model.body_mass[model.body(name).id] == pytest.approx(4.66)
        assert model.body_inertia[model.body(name).id][1] == pytest.approx(0.102019)


def test_sites_and_camera(model: mujoco.MjModel) -> None:
    """ee / ee_right at the gripper origins, tray_mount on the left gripper, camera track."""
    assert model.site("ee").bodyid == model.body("left_gripper").id
    assert model.site("ee_right").bodyid == model.body("right_gripper").id
    assert model.site("tray_mount").bodyid == model.body("left_gripper").id
    np.testing.assert_allclose(model.site("ee").pos, 0.0)
    np.testing.assert_allclose(model.site("ee_right").pos, 0.0)
    cam = model.camera("track")
    assert cam.bodyid == model.body("base").id
    assert cam.mode == mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM


def test_total_mass(model: mujoco.MjModel) -> None:
    """KrangOld total minus the kinect and the four gripper plates."""
    expected = FACTS_TOTAL_MASS - KINECT_MASS - 4 * PLATE_MASS
    assert model.body_mass.sum() == pytest.approx(expected, abs=1e-6)
    assert model.body_subtreemass[model.body("base").id] == pytest.approx(expected, abs=1e-6)


def test_home_pose(model: mujoco.MjModel) -> None:
    """Home: the paper's joint angles, base at the axle height, body CoM over the axle."""
    data = home(model)
    for name, value in HOME_JOINTS.items():
        assert data.joint(name).qpos[0] == pytest.approx(value)
    np.testing.assert_allclose(data.qpos[:3], [0.0, 0.0, 0.25])
    c = com(model, data)
    print(f"body CoM in the axle frame at home: {c}, distance {np.linalg.norm(c):.5f} m")
    assert abs(c[0]) < 1e-8
    assert c[2] > 0.25
    # the kinect (0.705 kg near the head) accounts for ~3 mm of the facts' 0.2921 m
    assert np.linalg.norm(c) == pytest.approx(FACTS_BODY_COM_DISTANCE, abs=0.005)
    # only the wheels touch the floor
    for contact in data.contact[: data.ncon]:
        names = {model.geom(contact.geom1).name, model.geom(contact.geom2).name}
        assert names & {"wheel_left", "wheel_right"}, names


def test_home_pitch_matches_qbase(model: mujoco.MjModel) -> None:
    """Our pitch (about +y, positive forward) equals 13b's qBase, same sign: R = Ry(qBase) R0.

    13b orients the base as Rx(pi/2) Ry(-pi/2) Rx(-qBase): Rx(pi/2) Ry(-pi/2) maps URDF x, y, z
    to -y, +z, -x (our base_link rotation) and Rx(-qBase) about URDF x = -y is Ry(+qBase).
    """
    pitch = base_pitch(home(model))
    print(f"home base pitch {pitch:.6f} rad (facts qBase {FACTS_QBASE}, with the kinect)")
    assert pitch < 0.0  # leaning back: the arms and spine reach forward of the axle
    assert pitch == pytest.approx(FACTS_QBASE, abs=0.006)  # the kinect explains ~4 mrad


def test_end_effectors_at_home(model: mujoco.MjModel) -> None:
    """EE (gripper origins) in the axle frame near the facts' frame-0 targets."""
    data = home(model)
    left = in_axle_frame(data, data.site("ee").xpos)
    right = in_axle_frame(data, data.site("ee_right").xpos)
    np.testing.assert_allclose(left, in_axle_frame(data, data.body("left_gripper").xpos))
    np.testing.assert_allclose(right, in_axle_frame(data, data.body("right_gripper").xpos))
    print(f"EE left {left}, right {right}")
    np.testing.assert_allclose(left, FACTS_EE_LEFT, atol=0.01)
    np.testing.assert_allclose(right, FACTS_EE_RIGHT, atol=0.01)
    tray = in_axle_frame(data, data.site("tray_mount").xpos)
    print(f"tray_mount {tray}")
    np.testing.assert_allclose(tray, FACTS_TRAY, atol=0.01)
    np.testing.assert_allclose(tray[:2], ((left + right) / 2)[:2], atol=0.005)


def test_with_kinect_reproduces_facts(model: mujoco.MjModel) -> None:
    """Put the kinect back: the derived facts (1.6) are reproduced to their rounding.

    This pins the frame conversion, the joint conventions and the URDF numbers.
    """
    full = with_kinect()
    assert full.body_mass.sum() == pytest.approx(FACTS_TOTAL_MASS - 4 * PLATE_MASS, abs=1e-6)
    data = home(full)
    pitch = balance(full, data)
    print(f"with kinect: pitch {pitch:.5f}, body CoM {np.linalg.norm(com(full, data)):.5f}")
    assert pitch == pytest.approx(FACTS_QBASE, abs=5e-4)
    assert np.linalg.norm(com(full, data)) == pytest.approx(FACTS_BODY_COM_DISTANCE, abs=1e-4)
    whole = com(full, data, wheels=True)
    assert whole[2] == pytest.approx(FACTS_WHOLE_COM_DISTANCE, abs=1e-4)
    left = in_axle_frame(data, data.site("ee").xpos)
    right = in_axle_frame(data, data.site("ee_right").xpos)
    np.testing.assert_allclose(left, FACTS_EE_LEFT, atol=1e-4)
    np.testing.assert_allclose(right, FACTS_EE_RIGHT, atol=1e-4)
    tray = in_axle_frame(data, data.site("tray_mount").xpos)
    np.testing.assert_allclose(tray, FACTS_TRAY, atol=1e-3)


def test_steps_from_home(model: mujoco.MjModel) -> None:
    """100 steps from home without control stay finite."""
    data = home(model)
    for _ in range(100):
        mujoco.mj_step(model, data)
    assert np.all(np.isfinite(data.qpos))
    assert np.all(np.isfinite(data.qvel))
    assert data.qpos[2] == pytest.approx(0.25, abs=0.01)
