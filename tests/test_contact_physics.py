"""Checks of the contact physics settings of assets/mjcf/common.xml (see assets/mjcf/README.md).

- Wheel-floor contact: with the wheel collision geom's priority, solref and solimp, a wheel
  driven at constant torque rolls with (almost) no slip.
- Tray-cup contact: the cup holds on a still tray tilted just below the friction angle
  ``atan(mu)`` and slides just above it.
- The tray-cup friction of a task model is the explicit pair's value, not MuJoCo's default
  combination (the larger of the two geoms' friction).
- Constraint islands are off: while the cup rides the tray a tray scene is one island, where
  the solve by islands gives the same bits; from a cup's loss to the next reset the env switches
  them on (the cup on the floor is an island of its own, which they converge on its own).

The small test models are built with ``MjSpec`` and take every number they share with the robots
(simulation options, wheel contact parameters, wheel mass and inertia, tray and cup sizes, the
tray-cup pair's solver parameters) from the compiled task models, so they follow common.xml and
wip_gym/scene.py if those change.
"""

from __future__ import annotations

import copy
import math

import mujoco
import numpy as np
import pytest

from wip_gym.scene import (
    CUP_HALF_HEIGHT,
    TRAY_HALF_SIZE,
    SceneOptions,
    add_cup,
    build_model,
    reset_qpos,
)

# every field of mjOption: a test model copies all of them from a compiled wip-gym model
OPTION_FIELDS = (
    "timestep",
    "integrator",
    "cone",
    "impratio",
    "solver",
    "iterations",
    "tolerance",
    "ls_iterations",
    "ls_tolerance",
    "noslip_iterations",
    "noslip_tolerance",
    "ccd_iterations",
    "ccd_tolerance",
    "sdf_iterations",
    "sdf_initpoints",
    "sleep_tolerance",
    "jacobian",
    "enableflags",
    "disableflags",
    "disableactuator",
    "gravity",
    "wind",
    "magnetic",
    "density",
    "viscosity",
    "o_margin",
    "o_solref",
    "o_solimp",
    "o_friction",
)

CHASSIS_MASS = 50.0  # kg, carried by the wheel (slides x and z only, no pitch)
WHEEL_TORQUE = 20.0  # N m
DRIVE_TIME = 2.0  # s
SLIP_SETTLE_TIME = 0.5  # s: slip is measured over the last 1.5 s of the drive
MAX_SLIP = 0.01  # m/s: the bound a wheel may slip at
# common.xml's nearly hard wheel contact: MuJoCo's default contact settings slip about 1.3e-3 m/s
# here, ours about 1.3e-5 m/s, so this bound tells them apart
SETTINGS_SLIP = 1e-4  # m/s

TILT_MARGIN = math.radians(1.0)
CUP_SETTLE_TIME = 0.1  # s: the cup's landing transient, excluded from the measurement
CUP_MEASURE_TIME = 2.0  # s
MAX_HOLD_CREEP = 0.002  # m
MIN_SLIDE = 0.02  # m


def _copy_options(spec: mujoco.MjSpec, model: mujoco.MjModel) -> None:
    for name in OPTION_FIELDS:
        setattr(spec.option, name, getattr(model.opt, name))


@pytest.fixture(scope="module")
def wip_model() -> mujoco.MjModel:
    return build_model(SceneOptions("wip"))


@pytest.fixture(scope="module")
def krang_cup_model() -> mujoco.MjModel:
    return build_model(SceneOptions("krang", tray=True, cup=True, cup_friction=0.3))


# ------------------------------------------------------------------------------ wheel slip
def _wheel_on_slides(wip: mujoco.MjModel) -> mujoco.MjModel:
    """A floor and one wheel of the wip (its contact geom, mass, inertia, hinge damping)
    carrying a chassis on slide x and slide z joints."""
    floor = wip.geom("floor")
    wheel_geom = wip.geom("wheel_left")
    wheel_body = wip.body("wheel_left")
    wheel_dof = wip.joint("wheel_left").dofadr[0]
    radius = float(wheel_geom.size[0])

    spec = mujoco.MjSpec()
    _copy_options(spec, wip)
    spec.worldbody.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0.0, 0.0, 0.05],
        condim=int(floor.condim[0]),
        friction=floor.friction,
        priority=int(floor.priority[0]),
        solref=floor.solref,
        solimp=floor.solimp,
    )
    chassis = spec.worldbody.add_body(
        name="chassis",
        pos=[0.0, 0.0, radius],
        mass=CHASSIS_MASS,
        inertia=[1.0, 1.0, 1.0],
        explicitinertial=True,
    )
    chassis.add_joint(name="x", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1.0, 0.0, 0.0])
    chassis.add_joint(name="z", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0.0, 0.0, 1.0])
    wheel = chassis.add_body(
        name="wheel",
        mass=float(wheel_body.mass[0]),
        inertia=wheel_body.inertia,
        explicitinertial=True,
    )
    wheel.add_joint(
        name="wheel",
        type=mujoco.mjtJoint.mjJNT_HINGE,
        axis=[0.0, 1.0, 0.0],
        damping=float(wip.dof_damping[wheel_dof]),
        armature=float(wip.dof_armature[wheel_dof]),
    )
    wheel.add_geom(
        name="wheel",
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=[radius, 0.0, 0.0],
        condim=int(wheel_geom.condim[0]),
        priority=int(wheel_geom.priority[0]),
        solref=wheel_geom.solref,
        solimp=wheel_geom.solimp,
        solmix=float(wheel_geom.solmix[0]),
        friction=wheel_geom.friction,
        margin=float(wheel_geom.margin[0]),
        gap=float(wheel_geom.gap[0]),
    )
    return spec.compile()


def test_wheel_model_matches_the_wip(wip_model: mujoco.MjModel) -> None:
    """The test wheel is the wip's (guards the copying above, and the numbers the test
    describes: radius 0.25 m, 4.66 kg, axial inertia 0.102 kg m^2, common.xml's contact)."""
    m = _wheel_on_slides(wip_model)
    g, ref = m.geom("wheel"), wip_model.geom("wheel_left")
    np.testing.assert_array_equal(g.size, ref.size)
    np.testing.assert_array_equal(g.solref, ref.solref)
    np.testing.assert_array_equal(g.solimp, ref.solimp)
    np.testing.assert_array_equal(g.friction, ref.friction)
    assert g.priority[0] == ref.priority[0] == 1
    assert g.size[0] == pytest.approx(0.25)
    assert m.body("wheel").mass[0] == pytest.approx(4.66)
    assert m.body("wheel").inertia[1] == pytest.approx(0.102)
    assert m.opt.timestep == wip_model.opt.timestep
    assert m.opt.integrator == wip_model.opt.integrator
    assert m.opt.cone == wip_model.opt.cone
    assert m.opt.impratio == wip_model.opt.impratio
    assert m.opt.disableflags == wip_model.opt.disableflags
    assert m.opt.enableflags == wip_model.opt.enableflags


@pytest.mark.parametrize("torque", [WHEEL_TORQUE, -WHEEL_TORQUE])
def test_wheel_driven_at_constant_torque_barely_slips(
    wip_model: mujoco.MjModel, torque: float
) -> None:
    """Constant wheel torque for 2 s: the contact point's speed |v_x - r omega| stays under
    1 cm/s over the last 1.5 s (the rolling acceleration needs about 78 N of traction against
    about 536 N of normal force, so an ideal no-slip contact would not slip at all)."""
    m = _wheel_on_slides(wip_model)
    d = mujoco.MjData(m)
    radius = float(m.geom("wheel").size[0])
    x_dof, wheel_dof = m.joint("x").dofadr[0], m.joint("wheel").dofadr[0]
    slips = []
    for _ in range(round(DRIVE_TIME / m.opt.timestep)):
        d.qfrc_applied[wheel_dof] = torque
        mujoco.mj_step(m, d)
        if d.time > SLIP_SETTLE_TIME + 1e-9:
            slips.append(d.qvel[x_dof] - radius * d.qvel[wheel_dof])
    max_slip = float(np.max(np.abs(slips)))
    travel = float(d.qpos[m.joint("x").qposadr[0]])
    assert np.sign(travel) == np.sign(torque) and abs(travel) > 0.5, travel
    assert max_slip < MAX_SLIP, f"max slip {max_slip:.3g} m/s (travel {travel:.3f} m)"
    assert max_slip < SETTINGS_SLIP, f"max slip {max_slip:.3g} m/s: wheel contact too soft"


# ------------------------------------------------------------------------------- cup on tray
def _tilted_tray_with_cup(
    reference: mujoco.MjModel, friction: float, tilt: float
) -> tuple[mujoco.MjModel, np.ndarray]:
    """A still tray (no joint) tilted about world y by ``tilt`` and the task's free cup
    (``wip_gym.scene.add_cup``: its geoms and its pairs with the plate) resting on it, exactly
    touching (as the env's reset places it), with the task model's options. Returns the model
    and the tray's rotation (columns: its axes in world; +x points downhill)."""
    quat = np.array([math.cos(tilt / 2), 0.0, math.sin(tilt / 2), 0.0])
    rotation = np.zeros(9)
    mujoco.mju_quat2Mat(rotation, quat)
    rotation = rotation.reshape(3, 3)

    spec = mujoco.MjSpec()
    _copy_options(spec, reference)
    spec.add_material(name="cup")
    tray = spec.worldbody.add_body(name="tray", quat=quat)
    tray.add_geom(
        name="tray",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=TRAY_HALF_SIZE,
        pos=[0.0, 0.0, TRAY_HALF_SIZE[2]],
        contype=0,
        conaffinity=0,
    )
    add_cup(spec, friction, 0.0)
    cup = spec.body("cup")
    cup.pos = rotation @ np.array([0.0, 0.0, 2 * TRAY_HALF_SIZE[2] + CUP_HALF_HEIGHT])
    cup.quat = quat
    spec.geom("cup").contype = spec.geom("cup").conaffinity = 0  # no floor here
    return spec.compile(), rotation


def _cup_travel_on_tray(
    reference: mujoco.MjModel, friction: float, tilt: float
) -> tuple[np.ndarray, np.ndarray]:
    """Simulate 2.1 s from rest. Returns, for every step after the first 0.1 s (the landing
    transient: the cup starts exactly touching, drops by the 1 ms free fall and sinks into the
    soft contact), the cup's displacement down the tray since t = 0.1 s and whether it still
    touches the tray."""
    m, rotation = _tilted_tray_with_cup(reference, friction, tilt)
    d = mujoco.MjData(m)
    downhill = rotation[:, 0]
    start = None
    travel, touching = [], []
    settle_steps = round(CUP_SETTLE_TIME / m.opt.timestep)
    for step in range(settle_steps + round(CUP_MEASURE_TIME / m.opt.timestep)):
        mujoco.mj_step(m, d)
        along = float(downhill @ d.qpos[:3])
        if step + 1 == settle_steps:
            start = along
        elif start is not None:
            travel.append(along - start)
            touching.append(d.ncon > 0)  # the pair is the model's only possible contact
    return np.array(travel), np.array(touching)


def test_tilted_tray_model_matches_the_task(krang_cup_model: mujoco.MjModel) -> None:
    """The still tray + cup model has the task's pairs (solver parameters, condim), options
    and sizes, and its geoms collide only through the pairs."""
    m, _ = _tilted_tray_with_cup(krang_cup_model, 0.3, 0.0)
    assert m.npair == krang_cup_model.npair
    for p in range(m.npair):
        name = m.pair(p).name
        ref_pair, pair = krang_cup_model.pair(name), m.pair(name)
        np.testing.assert_array_equal(pair.friction, ref_pair.friction)
        np.testing.assert_array_equal(pair.solref, ref_pair.solref)
        np.testing.assert_array_equal(pair.solimp, ref_pair.solimp)
        assert pair.dim[0] == ref_pair.dim[0] == 3
    for g in range(m.ngeom):
        name = m.geom(g).name
        np.testing.assert_array_equal(m.geom(name).size, krang_cup_model.geom(name).size)
        assert m.geom(name).contype[0] == m.geom(name).conaffinity[0] == 0
    assert m.body("cup").mass[0] == pytest.approx(krang_cup_model.body("cup").mass[0])
    assert m.opt.disableflags == krang_cup_model.opt.disableflags
    assert m.opt.impratio == krang_cup_model.opt.impratio


@pytest.mark.parametrize("mu", [0.3, 0.5])
def test_cup_holds_below_and_slides_above_the_friction_angle(
    krang_cup_model: mujoco.MjModel, mu: float
) -> None:
    """Tray tilted 1 degree below atan(mu): the cup moves < 2 mm in 2 s (it creeps, as MuJoCo's
    soft friction does, by a fraction of a millimetre per second). 1 degree above: it slides
    more than 2 cm down the tray while still on it (it then slides off the plate)."""
    hold, hold_touching = _cup_travel_on_tray(krang_cup_model, mu, math.atan(mu) - TILT_MARGIN)
    assert hold_touching.all()
    creep = float(np.max(np.abs(hold)))
    assert creep < MAX_HOLD_CREEP, f"cup crept {creep * 1e3:.2f} mm below the friction angle"

    slide, slide_touching = _cup_travel_on_tray(krang_cup_model, mu, math.atan(mu) + TILT_MARGIN)
    assert slide_touching.any()
    on_tray = float(np.max(slide[slide_touching]))
    assert on_tray > MIN_SLIDE, f"cup slid only {on_tray * 1e3:.2f} mm above the friction angle"


# ----------------------------------------------------------------------- pair friction in task
def test_tray_cup_friction_is_the_pair_value() -> None:
    """In a krang tray task model the tray-cup contact friction is the pair's ``cup_friction``:
    the tray geom collides with nothing by itself, so only the pair makes that contact, and the
    contacts carry 0.42 although both geoms have friction 1 (which MuJoCo's default combination,
    the larger of the two, would give)."""
    mu = 0.42
    m = build_model(SceneOptions("krang", tray=True, cup=True, cup_friction=mu))
    tray_geom = m.geom("tray")
    cup_geoms = {g for g in range(m.ngeom) if m.geom_bodyid[g] == m.body("cup").id}
    plate_pairs = [p for p in range(m.npair) if tray_geom.id in (m.pair_geom1[p], m.pair_geom2[p])]
    assert plate_pairs
    for p in plate_pairs:
        assert m.pair_friction[p][0] == mu
        assert {m.pair_geom1[p], m.pair_geom2[p]} - {tray_geom.id} <= cup_geoms
    assert tray_geom.contype[0] == tray_geom.conaffinity[0] == 0
    assert tray_geom.friction[0] != mu
    assert all(m.geom_friction[g][0] != mu for g in cup_geoms)

    # the robot's reset pose, held still by gravity compensation; the cup placed on the tray
    # as WIPEnv.reset_model does (exactly touching: no contact until it has dropped a little)
    d = mujoco.MjData(m)
    pose = reset_qpos(m)
    d.qpos[: len(pose)] = pose
    mujoco.mj_kinematics(m, d)
    tray = m.body("tray").id
    tray_rotation = d.xmat[tray].reshape(3, 3)
    cup_qpos = m.joint("cup").qposadr[0]
    d.qpos[cup_qpos : cup_qpos + 3] = d.xpos[tray] + tray_rotation @ np.array(
        [0.0, 0.0, 2 * TRAY_HALF_SIZE[2] + CUP_HALF_HEIGHT]
    )
    mujoco.mju_mat2Quat(d.qpos[cup_qpos + 3 : cup_qpos + 7], d.xmat[tray])
    mujoco.mj_forward(m, d)
    robot_dofs = m.nv - 6  # the cup's free joint comes last
    assert m.joint("cup").dofadr[0] == robot_dofs

    contacts = []
    for _ in range(20):
        d.qfrc_applied[:robot_dofs] = d.qfrc_bias[:robot_dofs]
        mujoco.mj_step(m, d)
        contacts = [
            c
            for c in d.contact[: d.ncon]
            if tray_geom.id in (c.geom1, c.geom2) and {c.geom1, c.geom2} & cup_geoms
        ]
        if contacts:
            break
    assert contacts, "the cup never touched the tray"
    for c in contacts:
        assert c.friction[0] == mu and c.friction[1] == mu
        assert c.dim == 3


def _islands_on(model: mujoco.MjModel) -> mujoco.MjModel:
    """A copy of ``model`` with MuJoCo's default: constraint islands on."""
    on = copy.copy(model)
    on.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_ISLAND)
    return on


@pytest.mark.parametrize("env_id", ["wip_gym/KrangTray-v0", "wip_gym/PlanarTray-v0"])
def test_islands_off_change_no_bit_while_the_cup_rides_the_tray(env_id: str) -> None:
    """Every 10th state of a controlled episode (``unified``, 0.4 s): one step with islands off
    (the model as built) and on (MuJoCo's default) gives the same ``qpos``, ``qvel`` and
    contact forces to the bit, and with islands on the scene is one island (the robot and the
    cup, two kinematic trees, joined by the cup's contacts)."""
    import gymnasium as gym

    from controllers.registry import make_policy

    env = gym.make(env_id)
    observation, info = env.reset(seed=3)
    policy = make_policy("unified", env)
    policy.reset(observation, info)
    model, data = env.unwrapped.model, env.unwrapped.data
    assert model.opt.disableflags & int(mujoco.mjtDisableBit.mjDSBL_ISLAND)
    on = _islands_on(model)
    compared = 0
    for step in range(400):
        observation, *_ = env.step(policy(observation))
        if step % 10:
            continue
        off_data, on_data = mujoco.MjData(model), mujoco.MjData(on)
        mujoco.mj_copyData(off_data, model, data)
        mujoco.mj_copyData(on_data, model, data)
        mujoco.mj_step(model, off_data)
        mujoco.mj_step(on, on_data)
        assert on_data.nisland == 1 and off_data.nisland == 0
        np.testing.assert_array_equal(off_data.qpos, on_data.qpos)
        np.testing.assert_array_equal(off_data.qvel, on_data.qvel)
        np.testing.assert_array_equal(off_data.efc_force, on_data.efc_force)
        compared += 1
    assert compared == 40 and info["cup_on_tray"]


def _island_bit(model: mujoco.MjModel) -> bool:
    return bool(model.opt.disableflags & int(mujoco.mjtDisableBit.mjDSBL_ISLAND))


def test_a_lost_cup_switches_islands_on_until_the_next_reset() -> None:
    """The cup knocked onto the floor (``terminate_on_cup_loss=False``): from the step that
    finds it lost the env's model has islands on and the scene is two of them (the robot, the
    cup); the next reset switches them off again, before its physics; a model whose islands the
    user switched on keeps them on through a loss and a reset."""
    import gymnasium as gym

    env = gym.make("wip_gym/KrangTray-v0", terminate_on_cup_loss=False)
    base = env.unwrapped
    env.reset(seed=0)
    model, data = base.model, base.data
    assert _island_bit(model)  # off as built
    joint = model.body("cup").jntadr[0]
    qpos, dof = model.jnt_qposadr[joint], model.jnt_dofadr[joint]
    data.qpos[qpos : qpos + 3] = data.qpos[0:3] + (0.6, 0.3, 0.0)
    data.qpos[qpos + 2] = CUP_HALF_HEIGHT - 1e-4  # resting on the floor
    data.qvel[dof : dof + 6] = (1.0, 0.3, 0.0, 0.0, 0.0, 0.0)  # and sliding
    mujoco.mj_forward(model, data)
    action = np.zeros(model.nu)
    _, _, terminated, _, info = env.step(action)
    assert not info["cup_on_tray"] and not terminated
    assert not _island_bit(model)  # on from the loss
    for _ in range(20):
        env.step(action)
        assert data.nisland == 2 and not _island_bit(model)
    env.reset(seed=1)
    assert _island_bit(model) and data.nisland == 0
    _, _, _, _, info = env.step(action)
    assert info["cup_on_tray"] and _island_bit(model)
    # the user's choice is kept: islands on by hand stay on through a loss and a reset
    model.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_ISLAND)
    data.qpos[qpos + 2] = -1.0  # the cup far below the tray: lost
    mujoco.mj_forward(model, data)
    env.step(action)
    env.reset(seed=2)
    assert not _island_bit(model)
