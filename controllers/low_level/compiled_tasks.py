"""The task stack of the whole-body QP as one compiled function of a per-step snapshot.

The tasks of ``controllers.low_level.tasks`` (and the disturbance observer of
``controllers.low_level.disturbance_tasks``) written once more as pure numba functions of arrays,
operation for operation: the Python objects stay the reference and the extension point (a task
of a new kind runs the Python path of ``controllers.low_level.task_qp``), and
``tests/test_compiled_tasks.py`` holds the two equal on random states of both robots. One call of
:func:`task_rows` fills the stacked rows ``J`` (over ``nu``), ``xdd*``, ``Jdot nu`` for every
task from

* the robot's minimal state and ``J_tf`` (``wip_gym.robot_model``),
* each task site's world pose and ``[jacp; jacr]`` at the robot's state, and the axle origin's
  position and ``jacp`` (``site_in_axle_frame``),
* the motion probe's idealised state (``controllers.low_level.motion_probe``): ``qvel``,
  ``qacc_0``, and for the origin and each site the world position, ``[jacp; jacr]`` and their
  time derivative (``mj_jacDot``); for the body CoM the subtree rows behind ``com_motion``,

and the tasks' parameters packed as arrays (:mod:`controllers.low_level.task_stack`). Paper
section "Optimization Based Control": ``xdd* = xdd_d - Kp (x - x_d) - Kv (xd - xd_d)``.

Why numba: at this size (Krang: 18 variables, 31 task rows) a task is a few dozen operations on
3-vectors; a NumPy call costs a microsecond before any arithmetic and a jitted JAX call tens of
microseconds (``benchmarks/speed/low_level_kernel_bench.py`` measures the three).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from wip_gym.small_linalg import matmul_pattern, small_matmul, small_matvec

THETA, SPIN, POSITION, ORIENTATION, POSTURE = 0, 1, 2, 3, 4
"""Task kinds (``kinds`` of :func:`task_rows`)."""

PARAMETERS = 5
"""Columns of ``params``: kp, kv, then theta: ``theta_d, thetad_d, thdd_d``; spin: ``psi_d,
psid_d, psidd_d``."""

_MIN_VALUE = 1e-15  # MuJoCo's mjMINVAL (mju_normalize3, mju_normalize4)


@njit(cache=True)
def mat2quat(mat: np.ndarray) -> np.ndarray:
    """``mju_mat2Quat`` of a 3x3 rotation (its branches, then ``mju_normalize4``)."""
    m = mat.ravel()
    quat = np.empty(4)
    if m[0] + m[4] + m[8] > 0:
        quat[0] = 0.5 * math.sqrt(1 + m[0] + m[4] + m[8])
        quat[1] = 0.25 * (m[7] - m[5]) / quat[0]
        quat[2] = 0.25 * (m[2] - m[6]) / quat[0]
        quat[3] = 0.25 * (m[3] - m[1]) / quat[0]
    elif m[0] > m[4] and m[0] > m[8]:
        quat[1] = 0.5 * math.sqrt(1 + m[0] - m[4] - m[8])
        quat[0] = 0.25 * (m[7] - m[5]) / quat[1]
        quat[2] = 0.25 * (m[1] + m[3]) / quat[1]
        quat[3] = 0.25 * (m[2] + m[6]) / quat[1]
    elif m[4] > m[8]:
        quat[2] = 0.5 * math.sqrt(1 - m[0] + m[4] - m[8])
        quat[0] = 0.25 * (m[2] - m[6]) / quat[2]
        quat[1] = 0.25 * (m[1] + m[3]) / quat[2]
        quat[3] = 0.25 * (m[5] + m[7]) / quat[2]
    else:
        quat[3] = 0.5 * math.sqrt(1 - m[0] - m[4] + m[8])
        quat[0] = 0.25 * (m[3] - m[1]) / quat[3]
        quat[1] = 0.25 * (m[2] + m[6]) / quat[3]
        quat[2] = 0.25 * (m[5] + m[7]) / quat[3]
    norm = math.sqrt(quat[0] ** 2 + quat[1] ** 2 + quat[2] ** 2 + quat[3] ** 2)
    if norm < _MIN_VALUE:
        quat[:] = 0.0
        quat[0] = 1.0
    elif abs(norm - 1.0) > _MIN_VALUE:
        quat *= 1.0 / norm
    return quat


@njit(cache=True)
def quat2vel(quat: np.ndarray) -> np.ndarray:
    """``mju_quat2Vel(quat, dt=1)``: the rotation vector of a unit quaternion."""
    axis = quat[1:4].copy()
    sin_half = math.sqrt(axis[0] ** 2 + axis[1] ** 2 + axis[2] ** 2)
    if sin_half < _MIN_VALUE:
        axis[:] = 0.0
        axis[0] = 1.0
    else:
        axis *= 1.0 / sin_half
    speed = 2 * math.atan2(sin_half, quat[0])
    if speed > math.pi:
        speed -= 2 * math.pi
    return axis * speed


@njit(cache=True)
def rotation_error(R: np.ndarray, R_target: np.ndarray) -> np.ndarray:
    """``log(R R_target^T)`` as ``controllers.low_level.tasks.rotation_error``."""
    quat = mat2quat(small_matmul(R, R_target.T))
    if quat[0] < 0:
        quat = -quat
    return quat2vel(quat)


@njit(cache=True)
def _to_axle(v: np.ndarray, c: float, s: float) -> np.ndarray:
    out = np.empty(3)
    out[0] = c * v[0] + s * v[1]
    out[1] = -s * v[0] + c * v[1]
    out[2] = v[2]
    return out


@njit(cache=True)
def relative_drift(
    p: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    p_o: np.ndarray,
    v_o: np.ndarray,
    a_o: np.ndarray,
    c: float,
    s: float,
    psid: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``MotionProbe.relative_drift``: a world point's position, velocity and drift
    acceleration relative to the axle midpoint in the axle frame (turning at ``psid``)."""
    rel = _to_axle(p - p_o, c, s)
    u = _to_axle(v - v_o, c, s)
    acc = _to_axle(a - a_o, c, s)
    w = psid
    rel_d = np.empty(3)
    rel_d[0] = u[0] + w * rel[1]
    rel_d[1] = u[1] - w * rel[0]
    rel_d[2] = u[2]
    rel_dd = np.empty(3)
    rel_dd[0] = acc[0] + 2.0 * w * u[1] - w * w * rel[0]
    rel_dd[1] = acc[1] - 2.0 * w * u[0] - w * w * rel[1]
    rel_dd[2] = acc[2]
    return rel, rel_d, rel_dd


@njit(cache=True)
def site_in_axle_frame(
    site_pos: np.ndarray,
    site_mat: np.ndarray,
    site_jac: np.ndarray,
    origin_pos: np.ndarray,
    origin_jac: np.ndarray,
    J_tf: np.ndarray,
    J_pattern: np.ndarray,
    c: float,
    s: float,
    index_psi: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``controllers.low_level.tasks.site_in_axle_frame`` from the site's world pose, its
    ``[jacp; jacr]`` and the origin's: ``(rel, R, Jp, Jr)`` over ``nu`` (``index_psi`` -1:
    planar, the axle frame is the world's; ``J_pattern``: ``RobotModel.J_tf_pattern``)."""
    jac = site_jac.copy()
    jac[:3] -= origin_jac
    JJ = matmul_pattern(jac, J_tf, J_pattern)
    R_world = site_mat.reshape(3, 3)
    if index_psi < 0:
        return site_pos - origin_pos, R_world.copy(), JJ[:3].copy(), JJ[3:].copy()
    Rt = np.zeros((3, 3))
    Rt[0, 0], Rt[0, 1], Rt[1, 0], Rt[1, 1], Rt[2, 2] = c, s, -s, c, 1.0
    rel = small_matvec(Rt, site_pos - origin_pos)
    Jp = small_matmul(Rt, JJ[:3])
    Jr = small_matmul(Rt, JJ[3:])
    Jp[0, index_psi] += rel[1]
    Jp[1, index_psi] -= rel[0]
    Jr[2, index_psi] -= 1.0
    return rel, small_matmul(Rt, R_world), Jp, Jr


@njit(cache=True)
def _observe(
    memory: np.ndarray, settings: np.ndarray, velocity: np.ndarray, reference: np.ndarray
) -> np.ndarray:
    """``DisturbanceRejectingTask.reference_acceleration`` on its ``memory`` (rows: estimate,
    previous velocity, previous command, ``[has previous, 0, 0]``) with ``settings`` ``(dt,
    alpha, bound)``; returns the command and advances the memory."""
    dt, alpha, bound = settings[0], settings[1], settings[2]
    estimate = memory[0]
    if memory[3, 0] != 0.0:
        for i in range(len(estimate)):
            measured = (velocity[i] - memory[1, i]) / dt - memory[2, i]
            value = estimate[i] + alpha * (measured - estimate[i])
            estimate[i] = min(max(value, -bound), bound)
    command = reference - estimate
    memory[1] = velocity
    memory[2] = command
    memory[3, 0] = 1.0
    return command


@njit(cache=True)
def _point_motion(
    jac: np.ndarray, jac_dot: np.ndarray, qvel: np.ndarray, qacc0: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``MotionProbe._point``: ``jac qvel`` and ``jac qacc_0 + jacDot qvel`` (6-vectors:
    linear then angular)."""
    return small_matvec(jac, qvel), small_matvec(jac, qacc0) + small_matvec(jac_dot, qvel)


@njit(cache=True)
def task_rows(
    kinds: np.ndarray,
    sites: np.ndarray,
    observers: np.ndarray,
    row_start: np.ndarray,
    params: np.ndarray,
    targets: np.ndarray,
    row_column: np.ndarray,
    row_target: np.ndarray,
    q: np.ndarray,
    nu: np.ndarray,
    J_tf: np.ndarray,
    J_pattern: np.ndarray,
    J_theta: np.ndarray,
    scalars: np.ndarray,
    bodies: np.ndarray,
    site_ids: np.ndarray,
    xpos: np.ndarray,
    site_xpos: np.ndarray,
    site_xmat: np.ndarray,
    site_jac: np.ndarray,
    origin_jac: np.ndarray,
    probe_qvel: np.ndarray,
    probe_qacc0: np.ndarray,
    probe_xpos: np.ndarray,
    probe_site_xpos: np.ndarray,
    probe_jac: np.ndarray,
    probe_jac_dot: np.ndarray,
    probe_subtree_com: np.ndarray,
    probe_xipos: np.ndarray,
    probe_subtree_linvel: np.ndarray,
    probe_cfrc_int: np.ndarray,
    subtree_mass: np.ndarray,
    gravity: np.ndarray,
    observer_memory: np.ndarray,
    observer_settings: np.ndarray,
    observer_advance: np.ndarray,
    J: np.ndarray,
    target: np.ndarray,
    jdot_nu: np.ndarray,
) -> None:
    """Fill ``J``, ``target`` (``xdd*``) and ``jdot_nu`` of the stacked tasks.

    ``q``, ``nu``, ``J_tf``, ``J_theta``: the robot's (``RobotModel``), ``J_pattern`` where
    ``J_tf`` may be nonzero (``RobotModel.J_tf_pattern``: the products with ``J_tf`` visit only
    those entries). ``scalars``: ``theta, thetad, cos psi, sin psi, psid, index_psi`` (-1
    planar). ``bodies``: ``(base, wheel_left, wheel_right)``; ``site_ids[i]``: the MuJoCo id of site
    slot ``i``. At the robot's state: ``xpos``, ``site_xpos``, ``site_xmat`` (MuJoCo's arrays),
    ``site_jac[i]`` (``mj_jacSite``), ``origin_jac`` (the base origin's ``jacp``). At the probe's
    idealised state: ``qvel``, ``qacc_0``, ``xpos``, ``site_xpos``, ``probe_jac[0]`` and its
    derivative for the origin, ``probe_jac[1 + i]`` for site slot ``i``, and ``subtree_com``,
    ``xipos``, ``subtree_linvel``, ``cfrc_int`` (read for a theta task only: the CoM drift of
    ``MotionProbe.com_motion``); ``subtree_mass``, ``gravity`` the model's. A task
    with ``observers[k] >= 0`` is wrapped by the disturbance observer of that slot, which
    advances when ``observer_advance[slot]`` is 1 and else gives its last command (the one of
    this state).
    """
    theta, thetad, c, s, psid = scalars[0], scalars[1], scalars[2], scalars[3], scalars[4]
    index_psi = int(scalars[5])
    base, left, right = bodies[0], bodies[1], bodies[2]
    qvel, qacc0 = probe_qvel, probe_qacc0
    n_sites = len(site_ids)
    n = len(nu)
    rel = np.zeros((n_sites, 3))
    R = np.zeros((n_sites, 3, 3))
    Jp = np.zeros((n_sites, 3, n))
    Jr = np.zeros((n_sites, 3, n))
    origin = xpos[base]
    for i in range(n_sites):
        site = site_ids[i]
        rel[i], R[i], Jp[i], Jr[i] = site_in_axle_frame(
            site_xpos[site],
            site_xmat[site],
            site_jac[i],
            origin,
            origin_jac,
            J_tf,
            J_pattern,
            c,
            s,
            index_psi,
        )
    v_o, a_o = _point_motion(probe_jac[0], probe_jac_dot[0], qvel, qacc0)
    p_o = probe_xpos[base]
    for k in range(len(kinds)):
        kind, start, stop = kinds[k], row_start[k], row_start[k + 1]
        kp, kv = params[k, 0], params[k, 1]
        J[start:stop] = 0.0
        if kind == THETA:
            J[start] = J_theta
            target[start] = (
                params[k, 4] - kp * (theta - params[k, 2]) - kv * (thetad - params[k, 3])
            )
            M, m_l, m_r = subtree_mass[base], subtree_mass[left], subtree_mass[right]
            mass = M - m_l - m_r
            com, xipos, linvel = probe_subtree_com, probe_xipos, probe_subtree_linvel
            force = probe_cfrc_int
            position = (M * com[base] - m_l * xipos[left] - m_r * xipos[right]) / mass
            velocity = (M * linvel[base] - m_l * linvel[left] - m_r * linvel[right]) / mass
            drift = (force[base, 3:] - force[left, 3:] - force[right, 3:]) / mass + gravity
            cp, cd, cdd = relative_drift(
                position, velocity, drift, p_o, v_o[:3], a_o[:3], c, s, psid
            )
            X, Z = cp[0], cp[2]
            D = X * X + Z * Z
            if D <= 1e-18:
                jdot_nu[start] = 0.0
            else:
                rate = (Z * cd[0] - X * cd[2]) / D
                jdot_nu[start] = (Z * cdd[0] - X * cdd[2]) / D - 2.0 * rate * (
                    X * cd[0] + Z * cd[2]
                ) / D
        elif kind == SPIN:
            J[start, index_psi] = 1.0
            target[start] = (
                params[k, 4] - kp * (q[index_psi] - params[k, 2]) - kv * (psid - params[k, 3])
            )
            jdot_nu[start] = 0.0
        elif kind in (POSITION, ORIENTATION):
            i = sites[k]
            v, a = _point_motion(probe_jac[1 + i], probe_jac_dot[1 + i], qvel, qacc0)
            if kind == POSITION:
                J[start:stop] = Jp[i]
                task_velocity = small_matvec(Jp[i], nu)
                reference = -kp * (rel[i] - targets[k, :3]) - kv * task_velocity
                jdot_nu[start:stop] = relative_drift(
                    probe_site_xpos[site_ids[i]], v[:3], a[:3], p_o, v_o[:3], a_o[:3], c, s, psid
                )[2]
            else:
                J[start:stop] = Jr[i]
                task_velocity = small_matvec(Jr[i], nu)
                error = rotation_error(R[i], targets[k].reshape(3, 3))
                reference = -kp * error - kv * task_velocity
                u = _to_axle(v[3:], c, s)
                acc = _to_axle(a[3:], c, s)
                jdot_nu[start] = acc[0] + psid * u[1]
                jdot_nu[start + 1] = acc[1] - psid * u[0]
                jdot_nu[start + 2] = acc[2]
            slot = observers[k]
            if slot >= 0:
                if observer_advance[slot]:
                    reference = _observe(
                        observer_memory[slot], observer_settings[slot], task_velocity, reference
                    )
                else:
                    reference = observer_memory[slot, 2].copy()
            target[start:stop] = reference
        else:  # POSTURE
            for row in range(start, stop):
                column = row_column[row]
                J[row, column] = 1.0
                target[row] = -kp * (q[column] - row_target[row]) - kv * nu[column]
                jdot_nu[row] = 0.0
