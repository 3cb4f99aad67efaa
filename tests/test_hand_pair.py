"""Two hands held as one rigid support (controllers/low_level/hand_pair.py) and the free tray's
seat on them (controllers/high_level/tray_seat.py), against MuJoCo.

The relative velocity and drift of the hand pair's rows against central differences of
MuJoCo's kinematics on random states of Krang that turn, pitch and move every joint; the
tray's seat against the env's own tray, settled on the finger plates at reset."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import wip_gym  # noqa: F401
from controllers.high_level.tray_seat import (
    TRAY_SHARE_PREFIX,
    TRAY_SINK_TIME,
    TraySeat,
    add_tray_shares,
)
from controllers.low_level.hand_pair import HandPair
from controllers.low_level.motion_probe import MotionProbe
from controllers.policy import controller_model, nominal_spec, task_info
from tests.robot_states import random_states, robot_at_reset
from wip_gym.robot_model import RobotModel
from wip_gym.scene import GRAVITY, TRAY_MASS

ENV = "wip_gym/KrangTray-v0"


def _setup():
    _, robot = robot_at_reset(ENV)
    model = robot.model
    sites = [model.site(name).id for name in ("ee", "ee_right")]
    return model, robot, sites


def _rotation_rate(R_plus: np.ndarray, R_minus: np.ndarray, eps: float) -> np.ndarray:
    """World angular velocity from two rotations ``2 eps`` apart (central difference)."""
    quat, vector = np.zeros(4), np.zeros(3)
    mujoco.mju_mat2Quat(quat, (R_plus @ R_minus.T).reshape(-1))
    mujoco.mju_quat2Vel(vector, quat, 2 * eps)
    return vector


def test_the_rows_equal_differences_of_mujoco_kinematics():
    model, robot, (a, b) = _setup()
    pair = HandPair(robot, a, b, weight=2.0, kp=0.0, kv=0.0)
    probe = MotionProbe(robot)
    other = RobotModel(model)
    rng = np.random.default_rng(4)
    eps = 1e-6
    for _ in range(5):
        q = robot.q + rng.uniform(-0.3, 0.3, robot.layout.n_min)
        nu = rng.uniform(-1.0, 1.0, robot.layout.n_min)
        xy = rng.uniform(-1, 1, 2)
        robot.update(*robot.full_state(q, nu, xy))
        probe.update(robot)
        J = pair.jacobian(robot)
        step = eps * nu[0] * np.array([np.cos(robot.psi), np.sin(robot.psi)])
        errors, rotations, rates = [], {a: [], b: []}, []
        for sign in (1.0, -1.0):
            other.update(*robot.full_state(q + sign * eps * nu, nu, xy + sign * step))
            errors.append(pair.errors(other)[0])
            for site in (a, b):
                rotations[site].append(other.data.site_xmat[site].reshape(3, 3).copy())
            rates.append(pair.jacobian(other) @ nu)
        # the position error's rate is the rows' linear part
        np.testing.assert_allclose(
            J[:3] @ nu, (errors[0] - errors[1]) / (2 * eps), rtol=1e-6, atol=1e-7
        )
        # the angular part: w_b - w_a, each from its rotation's difference
        w = [_rotation_rate(*rotations[site], eps) for site in (a, b)]
        np.testing.assert_allclose(J[3:] @ nu, w[1] - w[0], rtol=1e-6, atol=1e-7)
        # the drift: d/dt (J nu) at fixed nu
        drift = (rates[0] - rates[1]) / (2 * eps)
        assert np.abs(drift).max() > 0.05  # the states move: not trivially zero
        np.testing.assert_allclose(pair.drift(robot, probe), drift, rtol=1e-5, atol=1e-6)
        # the weighted rows: the PD law with these gains (0) is the drift itself
        A, c = pair.rows(robot, probe)
        np.testing.assert_allclose(A, 2.0 * J)
        np.testing.assert_allclose(c, 2.0 * pair.drift(robot, probe))


def test_the_pair_holds_only_the_relative_pose():
    """Zero error at the pose it was made at and wherever only the wheels and the heading
    change (the hands move together); an error when one arm moves."""
    model, robot, (a, b) = _setup()
    pair = HandPair(robot, a, b, weight=1.0, kp=1.0, kv=1.0)
    position, rotation = pair.errors(robot)
    assert np.abs(position).max() < 1e-12 and np.abs(rotation).max() < 1e-12
    q, nu = robot.q.copy(), np.zeros(robot.layout.n_min)
    q[0] += 0.4  # x
    robot.update(*robot.full_state(q, nu, (0.3, -0.2)))
    position, rotation = pair.errors(robot)
    assert np.abs(position).max() < 1e-9 and np.abs(rotation).max() < 1e-9
    q[-1] += 0.1  # the last joint: one arm's wrist
    robot.update(*robot.full_state(q, nu, (0.3, -0.2)))
    position, rotation = pair.errors(robot)
    assert np.abs(np.concatenate([position, rotation])).max() > 1e-3


def test_bad_input_is_refused():
    model, robot, (a, b) = _setup()
    with pytest.raises(ValueError, match="two different sites"):
        HandPair(robot, a, a, 1.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="not a site"):
        HandPair(robot, a, model.nsite, 1.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="kp"):
        HandPair(robot, a, b, 1.0, float("nan"), 1.0)


def _held(env, steps: int) -> None:
    """Step the env's physics ``steps`` times with the robot held at its pose, from the tray
    at rest (the reset gives it the hand's noisy velocity) and the cup lifted 5 m clear."""
    base = env.unwrapped
    m, d = base.model, base.data
    cup = m.joint("cup").qposadr[0]
    d.qpos[cup + 2] += 5.0
    robot_q = d.qpos[:25].copy()
    tray_dof = int(m.joint("tray").dofadr[0])
    d.qvel[tray_dof : tray_dof + 6] = 0.0
    for _ in range(steps):
        d.qpos[:25] = robot_q
        d.qvel[:tray_dof] = 0.0
        mujoco.mj_step(m, d)
    mujoco.mj_kinematics(m, d)


@pytest.mark.parametrize("rim", [0.0, 0.005])
@pytest.mark.parametrize("sink_s", [0.0, TRAY_SINK_TIME])
def test_the_seat_is_where_the_env_puts_the_tray(rim, sink_s):
    """The controller's nominal tray, seated at the reset pose, is the env's tray: without
    sinking, where the env placed it at reset; with it, where the env's tray is after as long
    with the robot held still. Same place and frame of the plate's top, on seeds whose reset
    noise turns the tray differently."""
    env = gym.make(ENV, tray_attachment="free", tray_rim=rim)
    robot = RobotModel(controller_model(env, "nominal"))
    options = task_info(env, "nominal").free_tray
    assert options is not None and options.tray_rim == rim
    seat = TraySeat(robot, options, sink_s=sink_s)
    assert robot.layout.nq == 25 == seat._tray_qpos
    site = robot.model.site("tray_top").id
    base = env.unwrapped
    env_site = base.model.site("tray_top").id
    turns = []
    for seed in range(4):
        observation, _ = env.reset(seed=seed)
        robot.update(observation["qpos"], observation["qvel"])
        before = robot.data.site_xmat[site].reshape(3, 3).copy()
        seat.seat(observation["qpos"])
        robot.update(observation["qpos"], observation["qvel"])
        _held(env, round(sink_s / base.model.opt.timestep))
        np.testing.assert_allclose(
            robot.data.site_xpos[site], base.data.site_xpos[env_site], atol=1e-9
        )
        R = robot.data.site_xmat[site].reshape(3, 3)
        np.testing.assert_allclose(R, base.data.site_xmat[env_site].reshape(3, 3), atol=1e-9)
        turns.append(np.degrees(np.arccos(np.clip((np.trace(R @ before.T) - 1) / 2, -1, 1))))
    assert max(turns) > 0.5  # the nominal weld was off by more than half a degree


def _horizontal_support_forces(m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
    """The generalised forces (``nv``) of the horizontal parts of the forces the free tray puts
    on its supports (Krang's finger plates), at their contact points."""
    tray = m.geom("tray").id
    total, force = np.zeros(m.nv), np.zeros(6)
    jacp = np.zeros((3, m.nv))
    for i in range(d.ncon):
        contact = d.contact[i]
        geoms = (int(contact.geom[0]), int(contact.geom[1]))
        if tray not in geoms:
            continue
        other = geoms[1] if geoms[0] == tray else geoms[0]
        mujoco.mj_contactForce(m, d, i, force)
        world = contact.frame.reshape(3, 3).T @ force[:3]  # on geom 2, from geom 1
        on_support = world if geoms[1] == other else -world
        on_support[2] = 0.0
        mujoco.mj_jac(m, d, jacp, None, contact.pos, int(m.geom_bodyid[other]))
        total += jacp.T @ on_support
    return total


def test_the_shared_tray_weighs_on_each_arm_as_the_env_tray_does():
    """With the tray's weight shared (``add_tray_shares``), the nominal model's gravity torques
    on the body joints (waist, torso, both arms) at the seat are the env's: its gravity and the
    free tray's contact forces on the finger plates, with the robot held still for the
    seat's sinking time (the cup lifted clear), less the horizontal parts of those forces (the
    plates' friction, internal forces between the two grippers that no mass gives). Without the
    share the right arm misses the part of the tray it carries. The parts' mass and centre of
    mass are the tray's."""
    env = gym.make(ENV, tray_attachment="free", tray_rim=0.0)
    base = env.unwrapped
    options = task_info(env, "nominal").free_tray
    assert options is not None
    spec = nominal_spec(env)
    assert add_tray_shares(spec, options) == [TRAY_SHARE_PREFIX + "right_gripper"]
    shared = RobotModel(spec.compile())
    whole = RobotModel(controller_model(env, "nominal"))
    seats = [TraySeat(robot, options) for robot in (shared, whole)]
    m = shared.model
    tray, share = m.body("tray").id, m.body(TRAY_SHARE_PREFIX + "right_gripper").id
    dofs = np.array(shared.layout.body_dof)  # every joint the floor's contacts do not load
    errors: dict[str, list[float]] = {"shared": [], "whole": []}
    for seed in range(4):
        observation, _ = env.reset(seed=seed)
        qpos, qvel = observation["qpos"], np.zeros(shared.layout.nv)
        _held(env, round(TRAY_SINK_TIME / base.model.opt.timestep))
        d = base.data
        d.qvel[: shared.layout.nv] = 0.0
        mujoco.mj_forward(base.model, d)
        # what holds the body still: gravity less what the floor and the tray's supports give
        env_torques = (d.qfrc_bias - d.qfrc_constraint)[dofs]
        friction = _horizontal_support_forces(base.model, d)[dofs]
        for name, robot, seat in zip(("shared", "whole"), (shared, whole), seats, strict=True):
            seat.seat(qpos)
            robot.update(qpos, qvel)
            mujoco.mj_forward(robot.model, robot.data)
            error = np.abs(robot.data.qfrc_bias[dofs] - env_torques - friction).max()
            errors[name].append(float(error))
        # the parts are the tray: its mass, and its centre of mass where the env's tray has it
        sd = shared.data
        mass = m.body_mass[tray] + m.body_mass[share]
        assert mass == pytest.approx(base.model.body_mass[base.model.body("tray").id], rel=1e-12)
        com = (m.body_mass[tray] * sd.xipos[tray] + m.body_mass[share] * sd.xipos[share]) / mass
        env_com = d.xipos[base.model.body("tray").id]
        np.testing.assert_allclose(com[:2], env_com[:2], atol=1e-3)
        assert 0.3 < seats[0].fractions["right_gripper"] < 0.7
    # N m: 1 % of the tray's weight half a metre from a joint (the tray, 0.2 s after it was
    # placed, still moves a little); the tray's whole weight there is 1 N m
    tolerance = 0.01 * TRAY_MASS * GRAVITY * 0.5
    assert max(errors["shared"]) < tolerance < 0.1 * min(errors["whole"])


def test_a_welded_tray_has_no_seat():
    env = gym.make(ENV, tray_attachment="welded")
    assert task_info(env, "nominal").free_tray is None
    robot = RobotModel(controller_model(env, "nominal"))
    options = dataclasses.replace(env.unwrapped.scene_options, tray_attachment="welded")
    with pytest.raises(ValueError, match="free tray"):
        TraySeat(robot, options)


def test_the_compiled_rows_equal_the_readable_rows():
    """``compiled_tasks.hand_pair_rows`` (the task QP's one-call step) against the readable rows
    (``J``, ``jdot_nu``, the target and the weights) to 1e-12 of their scale, on random states
    of Krang on and off the rolling manifold, with the pair held away from its reset pose."""
    from controllers.low_level.task_qp import QPSettings, TaskQP

    model, robot, (a, b) = _setup()
    pair = HandPair(robot, a, b, weight=3.0, kp=400.0, kv=40.0)
    low, high = model.actuator_ctrlrange.T.copy()
    compiled = TaskQP(robot, low, high, QPSettings())
    readable = TaskQP(robot, low, high, QPSettings(compiled_tasks=False))
    rng = np.random.default_rng(7)
    for qpos, qvel in random_states(robot, rng, 8):
        robot.update(qpos, qvel)
        kernels = []
        for qp in (compiled, readable):
            qp.assemble(robot, None, [pair], [])
            kernels.append(qp.kernel)
        assert compiled.compiled and not readable.compiled
        ours, theirs = kernels
        for name in ("J", "target", "jdot_nu", "w"):
            actual, expected = getattr(ours, name), getattr(theirs, name)
            scale = max(1.0, float(np.abs(expected).max()))
            np.testing.assert_allclose(actual, expected, rtol=0.0, atol=1e-12 * scale, err_msg=name)
        # the rows are not trivially zero: the pair is away from its pose and moving
        position, rotation = pair.errors(robot)
        assert np.abs(position).max() > 1e-3 and np.abs(rotation).max() > 1e-3
        assert np.abs(theirs.jdot_nu).max() > 1e-3 and np.abs(theirs.target).max() > 1e-1
