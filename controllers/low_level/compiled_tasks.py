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
section "Optimization Based Control": ``xdd* = xdd_d - Kp (x - x_d) - Kv (xd - xd_d)``, the one
PD law of every task, :func:`pd_acceleration`, which both paths call.

Why numba: at this size (Krang: 18 variables, 31 task rows) a task is a few dozen operations on
3-vectors; a NumPy call costs a microsecond before any arithmetic and a jitted JAX call tens of
microseconds (measured by ``benchmarks/speed/low_level_kernel_bench.py`` at the git tag
``lab-notebook``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

THETA, SPIN, POSITION, ORIENTATION, POSTURE = 0, 1, 2, 3, 4
"""Task kinds (``kinds`` of :func:`task_rows`)."""

PARAMETERS = 5
"""Columns of ``params``: kp, kv, then theta: ``theta_d, thetad_d, thdd_d``; spin: ``psi_d,
psid_d, psidd_d``."""

_MIN_VALUE = 1e-15  # MuJoCo's mjMINVAL (mju_normalize3, mju_normalize4)


def pd_acceleration(feedforward: Any, error: Any, rate_error: Any, kp: float, kv: float) -> Any:
    """The PD law of every task (paper section "Optimization Based Control"), written once:
    ``xdd* = xdd_d - Kp (x - x_d) - Kv (xd - xd_d)`` with ``feedforward = xdd_d`` (0 for a
    task that holds a place), ``error = x - x_d`` and ``rate_error = xd - xd_d``, floats or
    arrays. The Python tasks (``controllers.low_level.tasks``) call it, and :func:`task_rows`
    its compiled form; it lives in this file because numba keys the cache of a compiled
    function on its own file, so an edit here reaches both."""
    return feedforward - kp * error - kv * rate_error


_pd = njit(cache=True)(pd_acceleration)


@njit(cache=True)
def _mat2quat(
    m0: float,
    m1: float,
    m2: float,
    m3: float,
    m4: float,
    m5: float,
    m6: float,
    m7: float,
    m8: float,
) -> tuple[float, float, float, float]:
    """``mju_mat2Quat`` of a 3x3 rotation given row-major (its branches, then
    ``mju_normalize4``), as four floats."""
    if m0 + m4 + m8 > 0:
        q0 = 0.5 * math.sqrt(1 + m0 + m4 + m8)
        q1 = 0.25 * (m7 - m5) / q0
        q2 = 0.25 * (m2 - m6) / q0
        q3 = 0.25 * (m3 - m1) / q0
    elif m0 > m4 and m0 > m8:
        q1 = 0.5 * math.sqrt(1 + m0 - m4 - m8)
        q0 = 0.25 * (m7 - m5) / q1
        q2 = 0.25 * (m1 + m3) / q1
        q3 = 0.25 * (m2 + m6) / q1
    elif m4 > m8:
        q2 = 0.5 * math.sqrt(1 - m0 + m4 - m8)
        q0 = 0.25 * (m2 - m6) / q2
        q1 = 0.25 * (m1 + m3) / q2
        q3 = 0.25 * (m5 + m7) / q2
    else:
        q3 = 0.5 * math.sqrt(1 - m0 - m4 + m8)
        q0 = 0.25 * (m3 - m1) / q3
        q1 = 0.25 * (m2 + m6) / q3
        q2 = 0.25 * (m5 + m7) / q3
    norm = math.sqrt(q0**2 + q1**2 + q2**2 + q3**2)
    if norm < _MIN_VALUE:
        return 1.0, 0.0, 0.0, 0.0
    if abs(norm - 1.0) > _MIN_VALUE:
        scale = 1.0 / norm
        return q0 * scale, q1 * scale, q2 * scale, q3 * scale
    return q0, q1, q2, q3


@njit(cache=True)
def mat2quat(mat: np.ndarray) -> np.ndarray:
    """``mju_mat2Quat`` of a 3x3 rotation (its branches, then ``mju_normalize4``)."""
    m = mat.ravel()
    quat = np.empty(4)
    quat[0], quat[1], quat[2], quat[3] = _mat2quat(
        m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8]
    )
    return quat


@njit(cache=True)
def _quat2vel(q0: float, q1: float, q2: float, q3: float) -> tuple[float, float, float]:
    """``mju_quat2Vel(quat, dt=1)``: the rotation vector of a unit quaternion, as three
    floats."""
    sin_half = math.sqrt(q1**2 + q2**2 + q3**2)
    if sin_half < _MIN_VALUE:
        a0, a1, a2 = 1.0, 0.0, 0.0
    else:
        scale = 1.0 / sin_half
        a0, a1, a2 = q1 * scale, q2 * scale, q3 * scale
    speed = 2 * math.atan2(sin_half, q0)
    if speed > math.pi:
        speed -= 2 * math.pi
    return a0 * speed, a1 * speed, a2 * speed


@njit(cache=True)
def quat2vel(quat: np.ndarray) -> np.ndarray:
    """``mju_quat2Vel(quat, dt=1)``: the rotation vector of a unit quaternion."""
    out = np.empty(3)
    out[0], out[1], out[2] = _quat2vel(quat[0], quat[1], quat[2], quat[3])
    return out


@njit(cache=True)
def _rotation_error(R: np.ndarray, R_target: np.ndarray) -> tuple[float, float, float]:
    """``log(R R_target^T)`` as three floats (``R R_target^T`` summed in
    ``small_matmul``'s order)."""
    m = np.zeros(9)  # one small array: a tuple of nine would be rebuilt at every entry
    for i in range(3):
        for k in range(3):
            a = R[i, k]
            for j in range(3):
                m[3 * i + j] += a * R_target[j, k]
    q0, q1, q2, q3 = _mat2quat(m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8])
    if q0 < 0:
        q0, q1, q2, q3 = -q0, -q1, -q2, -q3
    return _quat2vel(q0, q1, q2, q3)


@njit(cache=True)
def rotation_error(R: np.ndarray, R_target: np.ndarray) -> np.ndarray:
    """``log(R R_target^T)`` as ``controllers.low_level.tasks.rotation_error``."""
    out = np.empty(3)
    out[0], out[1], out[2] = _rotation_error(R, R_target)
    return out


@njit(cache=True)
def _relative_drift(
    p: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    p_o: np.ndarray,
    v_o: np.ndarray,
    a_o: np.ndarray,
    c: float,
    s: float,
    psid: float,
    out: np.ndarray,
) -> None:
    """``MotionProbe.relative_drift`` into the rows of ``out`` (3 x 3): a world point's
    position, velocity and drift acceleration relative to the axle midpoint in the axle frame
    (turning at ``psid``); ``p``, ``v``, ``a`` and the origin's are read from their first
    three entries."""
    rel, rel_d, rel_dd = out[0], out[1], out[2]
    d0, d1 = p[0] - p_o[0], p[1] - p_o[1]
    r0, r1, r2 = c * d0 + s * d1, -s * d0 + c * d1, p[2] - p_o[2]
    d0, d1 = v[0] - v_o[0], v[1] - v_o[1]
    u0, u1, u2 = c * d0 + s * d1, -s * d0 + c * d1, v[2] - v_o[2]
    d0, d1 = a[0] - a_o[0], a[1] - a_o[1]
    acc0, acc1, acc2 = c * d0 + s * d1, -s * d0 + c * d1, a[2] - a_o[2]
    w = psid
    rel[0], rel[1], rel[2] = r0, r1, r2
    rel_d[0] = u0 + w * r1
    rel_d[1] = u1 - w * r0
    rel_d[2] = u2
    rel_dd[0] = acc0 + 2.0 * w * u1 - w * w * r0
    rel_dd[1] = acc1 - 2.0 * w * u0 - w * w * r1
    rel_dd[2] = acc2


@njit(cache=True)
def _heading_transpose(i: int, k: int, c: float, s: float) -> float:
    """Entry ``(i, k)`` of ``Rz(psi)^T = [[c, s, 0], [-s, c, 0], [0, 0, 1]]``."""
    if i == 2 or k == 2:
        return 1.0 if i == k else 0.0
    if i == k:
        return c
    return s if i == 0 else -s


@njit(cache=True)
def site_in_axle_frame_into(
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
    jac: np.ndarray,
    JJ: np.ndarray,
    rel: np.ndarray,
    R: np.ndarray,
    Jp: np.ndarray,
    Jr: np.ndarray,
) -> None:
    """``controllers.low_level.tasks.site_in_axle_frame`` from the site's world pose, its
    ``[jacp; jacr]`` and the origin's, into ``rel``, ``R``, ``Jp``, ``Jr`` (over ``nu``;
    ``index_psi`` -1: planar, the axle frame is the world's; ``J_pattern``:
    ``RobotModel.J_tf_pattern``), with ``jac`` (6 x nv) and ``JJ`` (6 x n) as scratch. The
    products are summed in the order of ``small_linalg``'s."""
    nv, n = jac.shape[1], JJ.shape[1]
    for i in range(6):
        for k in range(nv):
            jac[i, k] = site_jac[i, k] - origin_jac[i, k] if i < 3 else site_jac[i, k]
    JJ[:] = 0.0
    for e in range(J_pattern.shape[1]):  # matmul_pattern(jac, J_tf, J_pattern)
        r, col = J_pattern[0, e], J_pattern[1, e]
        value = J_tf[r, col]
        for i in range(6):
            JJ[i, col] += jac[i, r] * value
    if index_psi < 0:
        for i in range(3):
            rel[i] = site_pos[i] - origin_pos[i]
            for j in range(3):
                R[i, j] = site_mat[3 * i + j]
            for j in range(n):
                Jp[i, j] = JJ[i, j]
                Jr[i, j] = JJ[3 + i, j]
        return
    Jp[:] = 0.0
    Jr[:] = 0.0
    R[:] = 0.0
    for i in range(3):
        total = 0.0
        for k in range(3):
            total += _heading_transpose(i, k, c, s) * (site_pos[k] - origin_pos[k])
        rel[i] = total
        for k in range(3):
            a = _heading_transpose(i, k, c, s)
            for j in range(n):
                Jp[i, j] += a * JJ[k, j]
            for j in range(n):
                Jr[i, j] += a * JJ[3 + k, j]
            for j in range(3):
                R[i, j] += a * site_mat[3 * k + j]
    Jp[0, index_psi] += rel[1]
    Jp[1, index_psi] -= rel[0]
    Jr[2, index_psi] -= 1.0


@njit(cache=True)
def _observe(
    memory: np.ndarray,
    settings: np.ndarray,
    velocity: np.ndarray,
    reference: np.ndarray,
    command: np.ndarray,
) -> None:
    """``DisturbanceRejectingTask.reference_acceleration`` on its ``memory`` (rows: estimate,
    previous velocity, previous command, ``[has previous, 0, 0]``) with ``settings`` ``(dt,
    alpha, bound)``: the command into ``command``; advances the memory."""
    dt, alpha, bound = settings[0], settings[1], settings[2]
    estimate = memory[0]
    if memory[3, 0] != 0.0:
        for i in range(len(estimate)):
            measured = (velocity[i] - memory[1, i]) / dt - memory[2, i]
            value = estimate[i] + alpha * (measured - estimate[i])
            estimate[i] = min(max(value, -bound), bound)
    for i in range(len(command)):
        command[i] = reference[i] - estimate[i]
    memory[1] = velocity
    memory[2] = command
    memory[3, 0] = 1.0


@njit(cache=True)
def _point_motion(
    jac: np.ndarray,
    jac_dot: np.ndarray,
    qvel: np.ndarray,
    qacc0: np.ndarray,
    velocity: np.ndarray,
    drift: np.ndarray,
) -> None:
    """``MotionProbe._point``: ``jac qvel`` and ``jac qacc_0 + jacDot qvel`` (6-vectors:
    linear then angular) into ``velocity`` and ``drift``."""
    for i in range(6):
        v, a, b = 0.0, 0.0, 0.0
        for k in range(len(qvel)):
            v += jac[i, k] * qvel[k]
            a += jac[i, k] * qacc0[k]
            b += jac_dot[i, k] * qvel[k]
        velocity[i] = v
        drift[i] = a + b


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
    # every intermediate in arrays made once per call (a small array made per operation cost
    # about 30 ns and a reference count each: 111 of them per call before)
    rel = np.empty((n_sites, 3))
    R = np.empty((n_sites, 3, 3))
    Jp = np.empty((n_sites, 3, n))
    Jr = np.empty((n_sites, 3, n))
    jac, JJ = np.empty((6, site_jac.shape[2])), np.empty((6, n))
    v_o, a_o, v, a = np.empty(6), np.empty(6), np.empty(6), np.empty(6)
    drift3 = np.empty((3, 3))  # relative_drift's position, velocity, drift acceleration
    work = np.empty((3, 3))  # the CoM's position, velocity, drift (world); a task's velocity,
    # reference and command
    origin = xpos[base]
    for i in range(n_sites):
        site = site_ids[i]
        site_in_axle_frame_into(
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
            jac,
            JJ,
            rel[i],
            R[i],
            Jp[i],
            Jr[i],
        )
    _point_motion(probe_jac[0], probe_jac_dot[0], qvel, qacc0, v_o, a_o)
    p_o = probe_xpos[base]
    for k in range(len(kinds)):
        kind, start, stop = kinds[k], row_start[k], row_start[k + 1]
        kp, kv = params[k, 0], params[k, 1]
        J[start:stop] = 0.0
        if kind == THETA:
            J[start] = J_theta
            target[start] = _pd(params[k, 4], theta - params[k, 2], thetad - params[k, 3], kp, kv)
            M, m_l, m_r = subtree_mass[base], subtree_mass[left], subtree_mass[right]
            mass = M - m_l - m_r
            com, xipos, linvel = probe_subtree_com, probe_xipos, probe_subtree_linvel
            force = probe_cfrc_int
            for j in range(3):
                work[0, j] = (
                    M * com[base, j] - m_l * xipos[left, j] - m_r * xipos[right, j]
                ) / mass
                work[1, j] = (
                    M * linvel[base, j] - m_l * linvel[left, j] - m_r * linvel[right, j]
                ) / mass
                work[2, j] = (
                    force[base, 3 + j] - force[left, 3 + j] - force[right, 3 + j]
                ) / mass + gravity[j]
            _relative_drift(work[0], work[1], work[2], p_o, v_o, a_o, c, s, psid, drift3)
            cp, cd, cdd = drift3[0], drift3[1], drift3[2]
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
            target[start] = _pd(
                params[k, 4], q[index_psi] - params[k, 2], psid - params[k, 3], kp, kv
            )
            jdot_nu[start] = 0.0
        elif kind in (POSITION, ORIENTATION):
            i = sites[k]
            _point_motion(probe_jac[1 + i], probe_jac_dot[1 + i], qvel, qacc0, v, a)
            task_jacobian = Jp[i] if kind == POSITION else Jr[i]
            J[start:stop] = task_jacobian
            velocity, reference = work[0], work[1]
            for row in range(3):
                total = 0.0
                for j in range(n):
                    total += task_jacobian[row, j] * nu[j]
                velocity[row] = total
            if kind == POSITION:
                for row in range(3):
                    reference[row] = _pd(0.0, rel[i, row] - targets[k, row], velocity[row], kp, kv)
                _relative_drift(
                    probe_site_xpos[site_ids[i]], v, a, p_o, v_o, a_o, c, s, psid, drift3
                )
                for row in range(3):
                    jdot_nu[start + row] = drift3[2, row]
            else:
                e0, e1, e2 = _rotation_error(R[i], targets[k].reshape(3, 3))
                reference[0] = _pd(0.0, e0, velocity[0], kp, kv)
                reference[1] = _pd(0.0, e1, velocity[1], kp, kv)
                reference[2] = _pd(0.0, e2, velocity[2], kp, kv)
                u0, u1 = c * v[3] + s * v[4], -s * v[3] + c * v[4]
                acc0, acc1 = c * a[3] + s * a[4], -s * a[3] + c * a[4]
                jdot_nu[start] = acc0 + psid * u1
                jdot_nu[start + 1] = acc1 - psid * u0
                jdot_nu[start + 2] = a[5]
            slot = observers[k]
            if slot >= 0:
                command = work[2]
                if observer_advance[slot]:
                    _observe(
                        observer_memory[slot], observer_settings[slot], velocity, reference, command
                    )
                else:
                    command[:] = observer_memory[slot, 2]
                target[start:stop] = command
            else:
                target[start:stop] = reference
        else:  # POSTURE
            for row in range(start, stop):
                column = row_column[row]
                J[row, column] = 1.0
                target[row] = _pd(0.0, q[column] - row_target[row], nu[column], kp, kv)
                jdot_nu[row] = 0.0
