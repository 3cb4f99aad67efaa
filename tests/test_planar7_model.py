"""The planar7 robot (assets/mjcf/planar7.xml): sizes, limits, the home pose and a short drop.

The numbers checked here are the design targets of planar7.xml (docs/DESIGN.md §5: Krang's scale,
about 160 kg, body CoM about 0.3 m above the axle in the tray-carrying pose).
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
from conftest import home_data

ROOT = Path(__file__).parents[1]
SCENE = ROOT / "assets/mjcf/scene_planar7.xml"
GENERATOR = ROOT / "tools/build_planar7_mjcf.py"

JOINTS = [
    "root_x",
    "root_z",
    "root_pitch",
    "wheel_left",
    "wheel_right",
    "spine",
    "torso",
    "shoulder",
    "elbow",
    "wrist",
]
BODY_JOINTS = ["spine", "torso", "shoulder", "elbow", "wrist"]
# (actuator = joint name, torque limit N m): wheels as the authors' sim, body joints Krang's QP
ACTUATORS = [
    ("wheel_left", 150.0),
    ("wheel_right", 150.0),
    ("spine", 740.0),
    ("torso", 370.0),
    ("shoulder", 370.0),
    ("elbow", 175.0),
    ("wrist", 40.0),
]
WHEEL_RADIUS = 0.25


@pytest.fixture(scope="module")
def model(scene_model) -> mujoco.MjModel:
    return scene_model("planar7")


def body_com_in_axle_frame(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """CoM of every robot body except the wheels, relative to the axle midpoint (base origin)."""
    base = model.body("base").id
    wheels = {model.body("wheel_left").id, model.body("wheel_right").id}
    ids = [b for b in range(model.nbody) if model.body_rootid[b] == base and b not in wheels]
    masses = model.body_mass[ids]
    return masses @ data.xipos[ids] / masses.sum() - data.xpos[base]


def test_sizes_and_joint_order(model: mujoco.MjModel) -> None:
    assert model.nq == model.nv == 10  # 3 root + 2 wheels + 5 body joints
    assert [model.joint(j).name for j in range(model.njnt)] == JOINTS
    slide, hinge = mujoco.mjtJoint.mjJNT_SLIDE, mujoco.mjtJoint.mjJNT_HINGE
    types = [model.joint(name).type[0] for name in JOINTS]
    assert types == [slide, slide] + [hinge] * 8
    np.testing.assert_array_equal(model.joint("root_x").axis, [1, 0, 0])
    np.testing.assert_array_equal(model.joint("root_z").axis, [0, 0, 1])
    for name in JOINTS[2:]:
        np.testing.assert_array_equal(model.joint(name).axis, [0, 1, 0])
        assert model.body(model.joint(name).bodyid[0]).name != "world"
    for name in JOINTS[:3]:
        assert model.body(model.joint(name).bodyid[0]).name == "base"


def test_actuators(model: mujoco.MjModel) -> None:
    assert model.nu == 7
    for a, (name, limit) in enumerate(ACTUATORS):
        act = model.actuator(a)
        assert act.name == name
        assert model.joint(act.trnid[0]).name == name
        assert act.gear[0] == 1.0
        assert act.ctrllimited[0]
        np.testing.assert_array_equal(act.ctrlrange, [-limit, limit])


def test_total_mass(model: mujoco.MjModel) -> None:
    total = model.body_subtreemass[model.body("base").id]
    assert 150.0 <= total <= 170.0


def test_wheel_collision_geoms(model: mujoco.MjModel) -> None:
    for side, y in (("left", 0.34), ("right", -0.34)):
        geom = model.geom(f"wheel_{side}")
        assert geom.type[0] == mujoco.mjtGeom.mjGEOM_SPHERE
        assert geom.size[0] == pytest.approx(WHEEL_RADIUS)
        assert model.body(geom.bodyid[0]).name == f"wheel_{side}"
        np.testing.assert_allclose(model.body(f"wheel_{side}").pos, [0.0, y, 0.0])


def test_named_parts(model: mujoco.MjModel) -> None:
    for body in ("base", "spine", "torso", "upper_arm", "forearm", "hand"):
        assert model.body(body).mass[0] > 0
    assert model.site("ee").bodyid[0] == model.body("hand").id
    np.testing.assert_array_equal(model.site("tray_mount").pos, model.site("ee").pos)
    camera = model.camera("track")
    assert camera.mode[0] == mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM
    assert camera.bodyid[0] == model.body("base").id


def test_joint_limits(model: mujoco.MjModel) -> None:
    for name in JOINTS[:5]:  # root and wheels unlimited
        assert not model.joint(name).limited[0]
    for name in BODY_JOINTS:
        assert model.joint(name).limited[0]


def test_home_body_com_over_axle(model: mujoco.MjModel) -> None:
    data = home_data(model)
    assert data.qpos[model.joint("root_z").qposadr[0]] == WHEEL_RADIUS
    np.testing.assert_allclose(data.xpos[model.body("base").id], [0.0, 0.0, WHEEL_RADIUS])
    com = body_com_in_axle_frame(model, data)
    theta = math.atan2(com[0], com[2])
    assert abs(theta) < 1e-9
    assert 0.25 <= com[2] <= 0.35


def test_home_end_effector(model: mujoco.MjModel) -> None:
    data = home_data(model)
    ee = data.site("ee").xpos
    axle = data.xpos[model.body("base").id]
    assert 0.5 <= ee[2] <= 0.9  # above the floor (z = 0)
    assert ee[0] > axle[0]
    # the hand points straight up: the ee frame is world-aligned, a tray on it is level
    np.testing.assert_allclose(data.site("ee").xmat.reshape(3, 3), np.eye(3), atol=1e-12)


def test_home_inside_joint_ranges(model: mujoco.MjModel) -> None:
    data = home_data(model)
    for name in BODY_JOINTS:
        joint = model.joint(name)
        q = data.qpos[joint.qposadr[0]]
        lo, hi = joint.range
        assert lo + 0.1 <= q <= hi - 0.1, f"{name} = {q:.3f} not inside [{lo}, {hi}] by 0.1"


def test_home_gravity_torques_within_limits(model: mujoco.MjModel) -> None:
    data = home_data(model)
    for name, limit in ACTUATORS[2:]:
        torque = data.qfrc_bias[model.joint(name).dofadr[0]]
        assert abs(torque) < 0.75 * limit, f"{name} needs {torque:.1f} N m to hold home"


def test_home_only_wheels_touch_floor(model: mujoco.MjModel) -> None:
    data = home_data(model)
    floor = model.geom("floor").id
    contacts = data.contact[: data.ncon]
    assert all(floor in (c.geom1, c.geom2) for c in contacts)
    touching = {int(c.geom1 + c.geom2 - floor) for c in contacts}
    assert touching == {model.geom("wheel_left").id, model.geom("wheel_right").id}


def test_zero_control_steps(model: mujoco.MjModel) -> None:
    data = home_data(model)
    floor = model.geom("floor").id
    wheels = {model.geom("wheel_left").id, model.geom("wheel_right").id}
    data.ctrl[:] = 0.0
    for step in range(200):
        mujoco.mj_step(model, data)
        assert np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel)), step
        if step < 50:
            touching = {
                int(c.geom1 + c.geom2 - floor)
                for c in data.contact[: data.ncon]
                if floor in (c.geom1, c.geom2)
            }
            assert wheels <= touching, f"a wheel left the floor at step {step}"


def test_keyframe_matches_generator(model: mujoco.MjModel) -> None:
    spec = importlib.util.spec_from_file_location("build_planar7_mjcf", GENERATOR)
    assert spec is not None and spec.loader is not None
    generator = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(generator)
    robot = mujoco.MjModel.from_xml_path(str(generator.MJCF))
    np.testing.assert_allclose(
        model.key("home").qpos, generator.solve_home(robot), rtol=0, atol=1e-12
    )


def test_contract_layout(model: mujoco.MjModel) -> None:
    from wip_gym.robot_model import RobotLayout

    layout = RobotLayout.from_model(model)
    assert layout.planar
    assert layout.n_min == 7  # x, q1 (root_pitch), spine, torso, shoulder, elbow, wrist
    assert layout.wheel_radius == pytest.approx(WHEEL_RADIUS)
    assert layout.wheel_separation == pytest.approx(0.68)
