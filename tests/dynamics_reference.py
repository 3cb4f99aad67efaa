"""Referees for the minimal-coordinate dynamics, written independently of ``RobotModel``.

``constrained_accelerations`` solves MuJoCo's own rigid-body dynamics (full mass matrix, bias and
passive forces, actuation) under the rolling constraints written as "the velocity of each wheel's
contact point is zero" (a KKT solve through the constraint's null space). It uses MuJoCo's
Jacobians of the wheel centres, ``mj_jac`` and ``mj_jacDot``, not ``J_tf``.

``sample_contact_states`` draws states of a robot with its wheels on the floor and torques for which
MuJoCo's contact solution keeps each wheel within a fraction of its friction cone.
"""

from __future__ import annotations

from collections.abc import Iterator

import mujoco
import numpy as np

from wip_gym.robot_model import RobotModel


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def constrained_accelerations(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    qvel: np.ndarray,
    ctrl: np.ndarray,
    robot: RobotModel,
    *,
    with_jdot: bool = True,
) -> np.ndarray:
    """MuJoCo's ``qacc`` for the rigid rolling constraints (no contact softness), by KKT.

    ``with_jdot=False`` imposes ``G qacc = 0`` instead of ``G qacc = -Gdot qvel``: the
    velocity-level form of MuJoCo's own constraint solver.
    """
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    data.qvel[:] = qvel
    data.ctrl[:] = ctrl
    mujoco.mj_forward(model, data)
    nv = model.nv
    M = np.zeros((nv, nv))
    mujoco.mj_fullM(model, data, M)
    force = data.qfrc_actuator - data.qfrc_bias + data.qfrc_passive
    radius = robot.layout.wheel_radius
    down = _skew(np.array([0.0, 0.0, radius]))  # r_contact - r_centre = -radius e_z
    rows, rhs = [], []
    for wheel in robot.layout.wheel_bodies:
        jacp, jacr = np.zeros((3, nv)), np.zeros((3, nv))
        jacp_dot, jacr_dot = np.zeros((3, nv)), np.zeros((3, nv))
        centre = data.xpos[wheel]
        mujoco.mj_jac(model, data, jacp, jacr, centre, wheel)
        mujoco.mj_jacDot(model, data, jacp_dot, jacr_dot, centre, wheel)
        # contact-point velocity v_c + w x (-r e_z) = (Jp + [r e_z]x Jr) qvel; the contact point
        # moves with the centre, so its rate is (Jp_dot + [r e_z]x Jr_dot) qvel
        rows.append(jacp + down @ jacr)
        rhs.append(-(jacp_dot + down @ jacr_dot) @ qvel if with_jdot else np.zeros(3))
    G = np.vstack(rows)
    g = np.concatenate(rhs)
    _, s, vt = np.linalg.svd(G)
    rank = int((s > 1e-10 * s[0]).sum())
    null = vt[rank:].T
    particular = np.linalg.lstsq(G, g, rcond=None)[0]
    z = np.linalg.solve(null.T @ M @ null, null.T @ (force - M @ particular))
    return particular + null @ z


def random_minimal_state(
    robot: RobotModel, rng: np.random.Generator, *, turning: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """A random minimal state around the robot's ``home`` keyframe (or upright), body joints
    strictly inside their limits."""
    model, lay = robot.model, robot.layout
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "home")
    if key >= 0:
        robot.update(model.key_qpos[key][: lay.nq], np.zeros(lay.nv))
        q = robot.q.copy()
    else:
        q = np.zeros(lay.n_min)
    nu = rng.normal(size=lay.n_min) * 0.5
    q[0] = rng.normal()
    if lay.index_psi is not None:
        q[lay.index_psi] = rng.uniform(-np.pi, np.pi)
        if not turning:
            nu[lay.index_psi] = 0.0
    q[lay.index_q1] += rng.normal() * 0.3
    first = lay.index_q1 + 1
    for k, dof in enumerate(lay.body_dof):
        joint = model.dof_jntid[dof]
        value = q[first + k] + rng.normal() * 0.2
        if model.jnt_limited[joint]:
            lo, hi = model.jnt_range[joint]
            value = float(np.clip(value, lo + 0.05, hi - 0.05))
        q[first + k] = value
    return q, nu


def sample_contact_states(
    robot: RobotModel,
    sim_model: mujoco.MjModel,
    rng: np.random.Generator,
    count: int,
    *,
    cone_fraction: float = 0.8,
    turning: bool = True,
    max_tries: int = 20000,
) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, mujoco.MjData]]:
    """Yield ``(qpos, qvel, ctrl, data)`` after ``mj_forward`` on ``sim_model`` (with the floor):
    both wheels on the floor (axle 1e-10 m below the touching height, so the contact is active),
    no other contact or constraint, each wheel's friction within ``cone_fraction`` of its cone."""
    lay = robot.layout
    data = mujoco.MjData(sim_model)
    floor = mujoco.mj_name2id(sim_model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    wheels = {
        mujoco.mj_name2id(sim_model, mujoco.mjtObj.mjOBJ_GEOM, name)
        for name in ("wheel_left", "wheel_right")
    }
    limits = sim_model.actuator_ctrlrange[:, 1]
    height = lay.root_qpos + (1 if lay.planar else 2)
    produced = 0
    for _ in range(max_tries):
        q, nu = random_minimal_state(robot, rng, turning=turning)
        qpos, qvel = robot.full_state(q, nu)
        qpos[height] -= 1e-10
        ctrl = rng.uniform(-0.1, 0.1, size=sim_model.nu) * limits
        ctrl[list(lay.wheel_actuators)] *= 3.0
        mujoco.mj_resetData(sim_model, data)
        data.qpos[: lay.nq] = qpos
        data.qvel[: lay.nv] = qvel
        data.ctrl[:] = ctrl
        mujoco.mj_forward(sim_model, data)
        if data.ncon != 2 or data.nefc != 6:
            continue
        pairs = {(c.geom1, c.geom2) for c in data.contact[: data.ncon]}
        if not all(floor in p and (set(p) - {floor}) <= wheels for p in pairs):
            continue
        frame = np.zeros(6)
        friction_ok = True
        for i in range(data.ncon):
            mujoco.mj_contactForce(sim_model, data, i, frame)
            mu = data.contact[i].friction[0]
            if frame[0] <= 0 or np.hypot(frame[1], frame[2]) > cone_fraction * mu * frame[0]:
                friction_ok = False
        if not friction_ok:
            continue
        yield qpos, qvel, ctrl, data
        produced += 1
        if produced == count:
            return
    raise RuntimeError(f"only {produced} of {count} admissible contact states in {max_tries} tries")
