"""The task and constraint rows of the whole-body QP as compiled functions of a per-step snapshot.

The tasks of ``controllers.low_level.tasks`` (and the disturbance observer of
``controllers.low_level.disturbance_tasks``) written once more as numba functions of arrays,
operation for operation: the Python objects stay the reference and the extension point (a task
without compiled rows runs the task QP's readable path), and ``tests/test_compiled_tasks.py``
holds the two equal on random states of both robots.

Each compiled kind is one function, ``rows(table, item, p, M, first, drift, second)``, that
fills one task's rows of the one-call step (``controllers.low_level.compiled_step``):

* ``table``: the step's arrays (:data:`STEP`): the robot model's state and ``J_tf``, each task
  site's world pose and ``[jacp; jacr]`` at the robot's state and its frame in the axle frame
  (``site_in_axle_frame``), the motion probe's idealised state (``controllers.low_level.
  motion_probe``: ``qvel``, ``qacc_0``, and for the origin and each site the world position,
  ``[jacp; jacr]`` and their time derivative; for the body CoM the subtree rows behind
  ``com_motion``);
* ``item``: its row of the stack's ``items`` (:data:`ITEM`: its site slot, its columns);
* ``p``: its parameters, copied from the task object every step in the order of its
  ``parameters()``;
* ``M, first, drift, second``: its rows of the QP: for a task ``J`` (over ``nu``), ``xdd*``,
  ``Jdot nu`` and the weights; for a constraint ``G``, the lower bound, ``Jdot nu`` and the
  upper bound on ``G nu_dot + Jdot nu``. ``M`` comes zeroed.

:func:`kind_rows` is the registry: a task class names its kind (``compiled_kind``), and the
kind's function is called from there. Paper section "Optimization Based Control": ``xdd* =
xdd_d - Kp (x - x_d) - Kv (xd - xd_d)``, the one PD law of every task, :func:`pd_acceleration`,
which both paths call.

Why numba: at this size (Krang: 18 variables, 31 task rows) a task is a few dozen operations on
3-vectors; a NumPy call costs a microsecond before any arithmetic and a jitted JAX call tens of
microseconds (docs/performance.md).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from controllers.low_level.kernel import KERNEL
from wip_gym.array_table import (
    FLOAT_CUBE,
    FLOAT_MATRIX,
    FLOAT_VECTOR,
    INT_MATRIX,
    INT_VECTOR,
    TableSpec,
    field_offsets,
    float_cube,
    float_matrix,
    float_vector,
    int_vector,
)
from wip_gym.scene import GRAVITY

THETA, SPIN, POSITION, ORIENTATION, POSTURE, ACCELERATION_BOUND = 0, 1, 2, 3, 4, 5
TANGENTIAL_FORCE, AXLE_ACCELERATION, OBJECT_BALANCE = 6, 7, 8
HAND_PAIR = 9
"""The compiled kinds (a task class's ``compiled_kind``; :func:`kind_rows` calls each one's
function)."""

ITEM, ITEM_FIELDS = field_offsets(
    "item",
    (
        ("kind", 1),
        ("row", 1),  # its first row (of the tasks' rows, or of the constraints')
        ("rows", 1),
        ("parameter", 1),  # its first parameter
        ("parameters", 1),
        ("column", 1),  # its first column (posture-like items)
        ("site", 1),  # its site slot (-1: none)
        ("observer", 1),  # its observer slot (-1: none)
        ("paired_site", 1),  # its second site's slot (-1: none; a hand pair's hand b)
    ),
)
"""The columns of the stack's ``items``: one row per task, then per constraint."""

STEP = TableSpec(
    "step",
    (
        # the model's, the robot data's and the motion probe's data's addresses
        ("mujoco", INT_VECTOR),
        # the robot model's update (wip_gym.robot_model), written in place by every update
        ("robot_scalars", FLOAT_VECTOR),
        ("J_theta", FLOAT_VECTOR),
        ("J_tf", FLOAT_MATRIX),
        ("J_pattern", INT_MATRIX),
        ("Jdot_tf_nu", FLOAT_VECTOR),
        ("origin_jac", FLOAT_MATRIX),
        # MuJoCo's arrays at the robot's state, and the model's
        ("xpos", FLOAT_MATRIX),
        ("site_xpos", FLOAT_MATRIX),
        ("site_xmat", FLOAT_MATRIX),
        ("subtree_mass", FLOAT_VECTOR),
        ("gravity", FLOAT_VECTOR),
        # the motion probe: the layout it idealises with, its data's arrays
        ("probe_layout", INT_VECTOR),
        ("body_qpos", INT_VECTOR),
        ("body_dof", INT_VECTOR),
        ("probe_constants", FLOAT_VECTOR),  # the wheel radius and separation
        ("probe_qpos", FLOAT_VECTOR),
        ("probe_qvel", FLOAT_VECTOR),
        ("probe_qacc", FLOAT_VECTOR),
        ("probe_qacc0", FLOAT_VECTOR),
        ("probe_xpos", FLOAT_MATRIX),
        ("probe_site_xpos", FLOAT_MATRIX),
        ("probe_subtree_com", FLOAT_MATRIX),
        ("probe_xipos", FLOAT_MATRIX),
        ("probe_subtree_linvel", FLOAT_MATRIX),
        ("probe_cfrc_int", FLOAT_MATRIX),
        # the stack: its counts, its items (ITEM), their parameters and columns
        ("stack_ints", INT_VECTOR),  # the number of tasks, whether a theta task is there
        ("items", INT_MATRIX),
        ("parameters", FLOAT_VECTOR),
        ("columns", INT_VECTOR),
        # the sites: ids and bodies, Jacobians (robot, probe), frames in the axle frame
        ("bodies", INT_VECTOR),  # base, left wheel, right wheel
        ("site_ids", INT_VECTOR),
        ("site_bodies", INT_VECTOR),
        ("site_jac", FLOAT_CUBE),
        ("probe_jac", FLOAT_CUBE),  # 0: the origin, 1 + i: site slot i
        ("probe_jac_dot", FLOAT_CUBE),
        ("site_rel", FLOAT_MATRIX),
        ("site_R", FLOAT_CUBE),
        ("site_Jp", FLOAT_CUBE),
        ("site_Jr", FLOAT_CUBE),
        # scratch: theta, thetad, cos psi, sin psi, psid, index_psi; the frames' products;
        # the origin's and a point's velocity and drift; a task's work rows
        ("scalars", FLOAT_VECTOR),
        ("frame_jac", FLOAT_MATRIX),
        ("frame_JJ", FLOAT_MATRIX),
        ("origin_motion", FLOAT_MATRIX),
        ("point_motion", FLOAT_MATRIX),
        ("work", FLOAT_MATRIX),
        ("drift", FLOAT_MATRIX),
        # the disturbance observers: memory (slot x 4 x rows), settings, advance flags, work
        ("observer_memory", FLOAT_CUBE),
        ("observer_settings", FLOAT_MATRIX),
        ("observer_advance", INT_VECTOR),
        ("observer_work", FLOAT_MATRIX),
    ),
    base=KERNEL,
)
"""The arrays of the one-call step (``controllers.low_level.compiled_step.rows_and_kernel``):
the kernel's (:data:`controllers.low_level.kernel.KERNEL`, its first rows), then the rows'
(``controllers.low_level.task_stack.CompiledTaskStack`` builds the table)."""
S = STEP.index

_MIN_VALUE = 1e-15  # MuJoCo's mjMINVAL (mju_normalize3, mju_normalize4)


def pd_acceleration(feedforward: Any, error: Any, rate_error: Any, kp: float, kv: float) -> Any:
    """The PD law of every task (paper section "Optimization Based Control"), written once:
    ``xdd* = xdd_d - Kp (x - x_d) - Kv (xd - xd_d)`` with ``feedforward = xdd_d`` (0 for a
    task that holds a place), ``error = x - x_d`` and ``rate_error = xd - xd_d``, floats or
    arrays. The Python tasks (``controllers.low_level.tasks``) call it, and the compiled rows
    its compiled form."""
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
    """``MotionProbe.point_motion``: ``jac qvel`` and ``jac qacc_0 + jacDot qvel`` (6-vectors:
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
def theta_rows(
    table: np.ndarray,
    item: np.ndarray,
    p: np.ndarray,
    J: np.ndarray,
    target: np.ndarray,
    jdot_nu: np.ndarray,
    w: np.ndarray,
) -> None:
    """``ThetaTask``: ``p = (kp, kv, theta_d, thetad_d, thdd_d, weight)``; ``Jdot nu`` from the
    CoM's drift relative to the axle (``MotionProbe.com_motion``, ``relative_drift``)."""
    scalars = float_vector(table[S.scalars])
    theta, thetad, c, s, psid = scalars[0], scalars[1], scalars[2], scalars[3], scalars[4]
    J[0] = float_vector(table[S.J_theta])
    target[0] = _pd(p[4], theta - p[2], thetad - p[3], p[0], p[1])
    w[0] = p[5]
    bodies = int_vector(table[S.bodies])
    base, left, right = bodies[0], bodies[1], bodies[2]
    subtree_mass = float_vector(table[S.subtree_mass])
    M, m_l, m_r = subtree_mass[base], subtree_mass[left], subtree_mass[right]
    mass = M - m_l - m_r
    com, xipos = float_matrix(table[S.probe_subtree_com]), float_matrix(table[S.probe_xipos])
    linvel = float_matrix(table[S.probe_subtree_linvel])
    force, gravity = float_matrix(table[S.probe_cfrc_int]), float_vector(table[S.gravity])
    work, drift3 = float_matrix(table[S.work]), float_matrix(table[S.drift])
    for j in range(3):
        work[0, j] = (M * com[base, j] - m_l * xipos[left, j] - m_r * xipos[right, j]) / mass
        work[1, j] = (M * linvel[base, j] - m_l * linvel[left, j] - m_r * linvel[right, j]) / mass
        work[2, j] = (
            force[base, 3 + j] - force[left, 3 + j] - force[right, 3 + j]
        ) / mass + gravity[j]
    origin = float_matrix(table[S.origin_motion])
    p_o = float_matrix(table[S.probe_xpos])[base]
    _relative_drift(work[0], work[1], work[2], p_o, origin[0], origin[1], c, s, psid, drift3)
    cp, cd, cdd = drift3[0], drift3[1], drift3[2]
    X, Z = cp[0], cp[2]
    D = X * X + Z * Z
    if D <= 1e-18:
        jdot_nu[0] = 0.0
    else:
        rate = (Z * cd[0] - X * cd[2]) / D
        jdot_nu[0] = (Z * cdd[0] - X * cdd[2]) / D - 2.0 * rate * (X * cd[0] + Z * cd[2]) / D


@njit(cache=True)
def spin_rows(
    table: np.ndarray,
    item: np.ndarray,
    p: np.ndarray,
    J: np.ndarray,
    target: np.ndarray,
    jdot_nu: np.ndarray,
    w: np.ndarray,
) -> None:
    """``SpinTask``: ``p = (kp, kv, psi_d, psid_d, psidd_d, weight)``; ``J`` is constant."""
    scalars = float_vector(table[S.scalars])
    psid, index_psi = scalars[4], int(scalars[5])
    q = float_vector(table[S.q])
    J[0, index_psi] = 1.0
    target[0] = _pd(p[4], q[index_psi] - p[2], psid - p[3], p[0], p[1])
    jdot_nu[0] = 0.0
    w[0] = p[5]


@njit(cache=True)
def _site_velocity(task_jacobian: np.ndarray, nu: np.ndarray, velocity: np.ndarray) -> None:
    """``task_jacobian nu`` (3 rows) into ``velocity``."""
    n = len(nu)
    for row in range(3):
        total = 0.0
        for j in range(n):
            total += task_jacobian[row, j] * nu[j]
        velocity[row] = total


@njit(cache=True)
def position_rows(
    table: np.ndarray,
    item: np.ndarray,
    p: np.ndarray,
    J: np.ndarray,
    target: np.ndarray,
    jdot_nu: np.ndarray,
    w: np.ndarray,
) -> None:
    """``FramePositionTask``: ``p = (kp, kv, target (3), weights (3))``; the site's position,
    ``Jp`` and drift relative to the axle in the axle frame (its site slot's)."""
    i = item[ITEM.site]
    scalars = float_vector(table[S.scalars])
    c, s, psid = scalars[2], scalars[3], scalars[4]
    kp, kv = p[0], p[1]
    task_jacobian = float_cube(table[S.site_Jp])[i]
    J[:] = task_jacobian
    work = float_matrix(table[S.work])
    velocity = work[0]
    _site_velocity(task_jacobian, float_vector(table[S.nu]), velocity)
    rel = float_matrix(table[S.site_rel])[i]
    for row in range(3):
        target[row] = _pd(0.0, rel[row] - p[2 + row], velocity[row], kp, kv)
        w[row] = p[5 + row]
    motion, origin = float_matrix(table[S.point_motion]), float_matrix(table[S.origin_motion])
    _point_motion(
        float_cube(table[S.probe_jac])[1 + i],
        float_cube(table[S.probe_jac_dot])[1 + i],
        float_vector(table[S.probe_qvel]),
        float_vector(table[S.probe_qacc0]),
        motion[0],
        motion[1],
    )
    base = int_vector(table[S.bodies])[0]
    site = int_vector(table[S.site_ids])[i]
    drift3 = float_matrix(table[S.drift])
    _relative_drift(
        float_matrix(table[S.probe_site_xpos])[site],
        motion[0],
        motion[1],
        float_matrix(table[S.probe_xpos])[base],
        origin[0],
        origin[1],
        c,
        s,
        psid,
        drift3,
    )
    for row in range(3):
        jdot_nu[row] = drift3[2, row]


@njit(cache=True)
def orientation_rows(
    table: np.ndarray,
    item: np.ndarray,
    p: np.ndarray,
    J: np.ndarray,
    target: np.ndarray,
    jdot_nu: np.ndarray,
    w: np.ndarray,
) -> None:
    """``FrameOrientationTask``: ``p = (kp, kv, target (3 x 3, row-major), weights (3))``; the
    site's rotation error ``log(R R_target^T)``, ``Jr`` and angular drift in the axle frame."""
    i = item[ITEM.site]
    scalars = float_vector(table[S.scalars])
    c, s, psid = scalars[2], scalars[3], scalars[4]
    kp, kv = p[0], p[1]
    task_jacobian = float_cube(table[S.site_Jr])[i]
    J[:] = task_jacobian
    work = float_matrix(table[S.work])
    velocity = work[0]
    _site_velocity(task_jacobian, float_vector(table[S.nu]), velocity)
    e0, e1, e2 = _rotation_error(float_cube(table[S.site_R])[i], p[2:11].reshape(3, 3))
    target[0] = _pd(0.0, e0, velocity[0], kp, kv)
    target[1] = _pd(0.0, e1, velocity[1], kp, kv)
    target[2] = _pd(0.0, e2, velocity[2], kp, kv)
    w[0], w[1], w[2] = p[11], p[12], p[13]
    motion = float_matrix(table[S.point_motion])
    v, a = motion[0], motion[1]
    _point_motion(
        float_cube(table[S.probe_jac])[1 + i],
        float_cube(table[S.probe_jac_dot])[1 + i],
        float_vector(table[S.probe_qvel]),
        float_vector(table[S.probe_qacc0]),
        v,
        a,
    )
    u0, u1 = c * v[3] + s * v[4], -s * v[3] + c * v[4]
    acc0, acc1 = c * a[3] + s * a[4], -s * a[3] + c * a[4]
    jdot_nu[0] = acc0 + psid * u1
    jdot_nu[1] = acc1 - psid * u0
    jdot_nu[2] = a[5]


@njit(cache=True)
def posture_rows(
    table: np.ndarray,
    item: np.ndarray,
    p: np.ndarray,
    J: np.ndarray,
    target: np.ndarray,
    jdot_nu: np.ndarray,
    w: np.ndarray,
) -> None:
    """``PostureTask``: ``p = (kp, kv, targets (one per column), weights (one per column))``;
    one row per column, ``J`` constant."""
    q, nu = float_vector(table[S.q]), float_vector(table[S.nu])
    columns = int_vector(table[S.columns])
    first, count = item[ITEM.column], item[ITEM.rows]
    kp, kv = p[0], p[1]
    for row in range(count):
        column = columns[first + row]
        J[row, column] = 1.0
        target[row] = _pd(0.0, q[column] - p[2 + row], nu[column], kp, kv)
        jdot_nu[row] = 0.0
        w[row] = p[2 + count + row]


@njit(cache=True)
def acceleration_bound_rows(
    table: np.ndarray,
    item: np.ndarray,
    p: np.ndarray,
    G: np.ndarray,
    lower: np.ndarray,
    bias: np.ndarray,
    upper: np.ndarray,
) -> None:
    """``AccelerationBound`` (a constraint): ``p = (lower, upper)`` per column, on each
    column's minimal acceleration (``G`` a unit row, no drift)."""
    columns = int_vector(table[S.columns])
    first, count = item[ITEM.column], item[ITEM.rows]
    for row in range(count):
        G[row, columns[first + row]] = 1.0
        lower[row] = p[row]
        bias[row] = 0.0
        upper[row] = p[count + row]


@njit(cache=True)
def _tray_point(
    table: np.ndarray, i: int, x: float, y: float, z: float, JJ: np.ndarray, out: np.ndarray
) -> None:
    """``ObjectBalance._point`` of the point ``(x, y, z)`` (tray frame) from site slot ``i``
    (world): its linear Jacobian over ``nu``, ``J_s - [r]x J_r``, into ``JJ[:3]`` and the
    angular one ``J_r`` into ``JJ[3:]`` (MuJoCo's at the robot's state times ``J_tf``); into
    the rows of ``out`` (4 x 3): its drift acceleration ``a_s + omega_drift x r + omega x
    (omega x r)``, ``omega`` and ``omega_drift`` (the probe's) and ``r = R (x, y, z)``, ``R``
    the site's rotation at the robot's state."""
    site_jac, J_tf = float_cube(table[S.site_jac])[i], float_matrix(table[S.J_tf])
    JJ[:] = 0.0
    for row in range(6):
        for k in range(J_tf.shape[0]):
            a = site_jac[row, k]
            if a != 0.0:
                for j in range(J_tf.shape[1]):
                    JJ[row, j] += a * J_tf[k, j]
    R = float_matrix(table[S.site_xmat])[int_vector(table[S.site_ids])[i]]
    r0 = R[0] * x + R[1] * y + R[2] * z
    r1 = R[3] * x + R[4] * y + R[5] * z
    r2 = R[6] * x + R[7] * y + R[8] * z
    for j in range(JJ.shape[1]):
        u, v, w = JJ[3, j], JJ[4, j], JJ[5, j]
        JJ[0, j] -= -r2 * v + r1 * w
        JJ[1, j] -= r2 * u - r0 * w
        JJ[2, j] -= -r1 * u + r0 * v
    motion = float_matrix(table[S.point_motion])
    vel, acc = motion[0], motion[1]
    _point_motion(
        float_cube(table[S.probe_jac])[1 + i],
        float_cube(table[S.probe_jac_dot])[1 + i],
        float_vector(table[S.probe_qvel]),
        float_vector(table[S.probe_qacc0]),
        vel,
        acc,
    )
    w0, w1, w2, d0, d1, d2 = vel[3], vel[4], vel[5], acc[3], acc[4], acc[5]
    c0, c1, c2 = w1 * r2 - w2 * r1, w2 * r0 - w0 * r2, w0 * r1 - w1 * r0  # omega x r
    out[0, 0] = acc[0] + (d1 * r2 - d2 * r1) + (w1 * c2 - w2 * c1)
    out[0, 1] = acc[1] + (d2 * r0 - d0 * r2) + (w2 * c0 - w0 * c2)
    out[0, 2] = acc[2] + (d0 * r1 - d1 * r0) + (w0 * c1 - w1 * c0)
    out[1, 0], out[1, 1], out[1, 2] = w0, w1, w2
    out[2, 0], out[2, 1], out[2, 2] = d0, d1, d2
    out[3, 0], out[3, 1], out[3, 2] = r0, r1, r2


@njit(cache=True)
def tangential_force_rows(
    table: np.ndarray,
    item: np.ndarray,
    p: np.ndarray,
    J: np.ndarray,
    target: np.ndarray,
    jdot_nu: np.ndarray,
    w: np.ndarray,
) -> None:
    """``TangentialForceTask`` (``controllers.low_level.object_tasks``): ``p = (place x,
    place y, weight)``; the tangential specific force at the object's place on the plate,
    ``(f_x, f_y) = J nu_dot + jdot_nu`` (tray frame, in g; ``ObjectBalance.tangential``),
    toward 0."""
    i = item[ITEM.site]
    JJ, out = float_matrix(table[S.frame_JJ]), np.empty((4, 3))
    _tray_point(table, i, p[0], p[1], 0.0, JJ, out)
    R = float_matrix(table[S.site_xmat])[int_vector(table[S.site_ids])[i]]
    d = out[0]
    for row in range(2):  # R^T's rows 0 and 1: R's columns
        a0, a1, a2 = R[row], R[3 + row], R[6 + row]
        for j in range(J.shape[1]):
            J[row, j] = (a0 * JJ[0, j] + a1 * JJ[1, j] + a2 * JJ[2, j]) / GRAVITY
        jdot_nu[row] = (a0 * d[0] + a1 * d[1] + a2 * (d[2] + GRAVITY)) / GRAVITY
        target[row] = 0.0
        w[row] = p[2]


@njit(cache=True)
def axle_acceleration_rows(
    table: np.ndarray,
    item: np.ndarray,
    p: np.ndarray,
    J: np.ndarray,
    target: np.ndarray,
    jdot_nu: np.ndarray,
    w: np.ndarray,
) -> None:
    """``AxleAccelerationTask``: ``p = (target, weight)``; ``xdd`` (``nu_dot[0]``) toward the
    target."""
    J[0, 0] = 1.0
    target[0] = p[0]
    jdot_nu[0] = 0.0
    w[0] = p[1]


@njit(cache=True)
def object_balance_rows(
    table: np.ndarray,
    item: np.ndarray,
    p: np.ndarray,
    G: np.ndarray,
    lower: np.ndarray,
    bias: np.ndarray,
    upper: np.ndarray,
) -> None:
    """``ObjectBalanceConstraint`` (a constraint): ``p = (place x, place y, height, the three
    moments of inertia per mass, the rows' map of the wrench (rows x 6, row-major), their
    constants (rows))``; ``ObjectBalance.rows``: ``G nu_dot + bias <= 0`` with ``(f, tau) = W
    nu_dot + w`` (``ObjectBalance.wrench``), ``G = rows W`` and ``bias = rows w + constants``."""
    i = item[ITEM.site]
    count = item[ITEM.rows]
    JJ, out = float_matrix(table[S.frame_JJ]), np.empty((4, 3))
    _tray_point(table, i, p[0], p[1], p[2], JJ, out)
    R = float_matrix(table[S.site_xmat])[int_vector(table[S.site_ids])[i]]
    inertia = p[3:6]
    rows, constants = p[6 : 6 + 6 * count], p[6 + 6 * count : 6 + 7 * count]
    W = np.empty(6)
    for j in range(G.shape[1]):
        for k in range(3):  # R^T J_c / g, I R^T J_r / g
            W[k] = (R[k] * JJ[0, j] + R[3 + k] * JJ[1, j] + R[6 + k] * JJ[2, j]) / GRAVITY
            W[3 + k] = (
                inertia[k] * (R[k] * JJ[3, j] + R[3 + k] * JJ[4, j] + R[6 + k] * JJ[5, j])
            ) / GRAVITY
        for row in range(count):
            total = 0.0
            for k in range(6):
                total += rows[6 * row + k] * W[k]
            G[row, j] = total
    d, omega, drift = out[0], out[1], out[2]
    t = np.empty(3)  # omega in the tray's axes
    for k in range(3):
        t[k] = R[k] * omega[0] + R[3 + k] * omega[1] + R[6 + k] * omega[2]
    It0, It1, It2 = inertia[0] * t[0], inertia[1] * t[1], inertia[2] * t[2]
    gyro = (t[1] * It2 - t[2] * It1, t[2] * It0 - t[0] * It2, t[0] * It1 - t[1] * It0)
    d2 = d[2] + GRAVITY
    for k in range(3):
        W[k] = (R[k] * d[0] + R[3 + k] * d[1] + R[6 + k] * d2) / GRAVITY
        spin = R[k] * drift[0] + R[3 + k] * drift[1] + R[6 + k] * drift[2]
        W[3 + k] = (inertia[k] * spin + gyro[k]) / GRAVITY
    for row in range(count):
        total = 0.0
        for k in range(6):
            total += rows[6 * row + k] * W[k]
        bias[row] = total + constants[row]
        lower[row] = -np.inf
        upper[row] = 0.0


@njit(cache=True)
def hand_pair_rows(
    table: np.ndarray,
    item: np.ndarray,
    p: np.ndarray,
    J: np.ndarray,
    target: np.ndarray,
    jdot_nu: np.ndarray,
    w: np.ndarray,
) -> None:
    """``HandPair`` (``controllers.low_level.hand_pair``): ``p = (kp, kv, weight, offset (3),
    rotation (3 x 3, row-major))``, its site slot hand ``a``'s, its paired slot hand ``b``'s;
    ``J = [J_b - J_P; Jr_b - Jr_a]`` (world, over ``nu``) with ``P`` the point ``offset`` of
    hand ``a``'s frame (``_tray_point``), ``jdot_nu`` the two drifts' difference, the target
    ``-kp (p_b - P, e_R) - kv J nu`` with ``e_R = log(R_b (R_a rotation)^T)``."""
    i, k = item[ITEM.site], item[ITEM.paired_site]
    kp, kv = p[0], p[1]
    JJ, out = float_matrix(table[S.frame_JJ]), np.empty((4, 3))
    _tray_point(table, i, p[3], p[4], p[5], JJ, out)
    site_jac, J_tf = float_cube(table[S.site_jac])[k], float_matrix(table[S.J_tf])
    for row in range(6):  # hand b's [jacp; jacr] J_tf, less P's
        for j in range(J.shape[1]):
            total = 0.0
            for c in range(J_tf.shape[0]):
                total += site_jac[row, c] * J_tf[c, j]
            J[row, j] = total - JJ[row, j]
    motion = float_matrix(table[S.point_motion])
    _point_motion(
        float_cube(table[S.probe_jac])[1 + k],
        float_cube(table[S.probe_jac_dot])[1 + k],
        float_vector(table[S.probe_qvel]),
        float_vector(table[S.probe_qacc0]),
        motion[0],
        motion[1],
    )
    drift_b = motion[1]
    for row in range(3):
        jdot_nu[row] = drift_b[row] - out[0, row]
        jdot_nu[3 + row] = drift_b[3 + row] - out[2, row]
    site_ids, site_xmat = int_vector(table[S.site_ids]), float_matrix(table[S.site_xmat])
    site_xpos = float_matrix(table[S.site_xpos])
    a, b = site_ids[i], site_ids[k]
    R_a, R_b = site_xmat[a].reshape(3, 3), site_xmat[b].reshape(3, 3)
    rotation = p[6:15].reshape(3, 3)
    R_target = np.zeros((3, 3))
    for r in range(3):
        for c in range(3):
            total = 0.0
            for m in range(3):
                total += R_a[r, m] * rotation[m, c]
            R_target[r, c] = total
    error = np.empty(6)
    r0 = out[3]  # R_a offset: P - p_a
    for row in range(3):
        error[row] = site_xpos[b, row] - (site_xpos[a, row] + r0[row])
    error[3], error[4], error[5] = _rotation_error(R_b, R_target)
    nu = float_vector(table[S.nu])
    for row in range(6):
        rate = 0.0
        for j in range(len(nu)):
            rate += J[row, j] * nu[j]
        target[row] = -kp * error[row] - kv * rate
        w[row] = p[2]


@njit(cache=True)
def kind_rows(
    kind: int,
    table: np.ndarray,
    item: np.ndarray,
    p: np.ndarray,
    M: np.ndarray,
    first: np.ndarray,
    drift: np.ndarray,
    second: np.ndarray,
) -> None:
    """The registry of compiled kinds: ``kind``'s rows function on one item's rows (module
    docstring). A new compiled kind adds its constant, its function and its line here."""
    if kind == THETA:
        theta_rows(table, item, p, M, first, drift, second)
    elif kind == SPIN:
        spin_rows(table, item, p, M, first, drift, second)
    elif kind == POSITION:
        position_rows(table, item, p, M, first, drift, second)
    elif kind == ORIENTATION:
        orientation_rows(table, item, p, M, first, drift, second)
    elif kind == POSTURE:
        posture_rows(table, item, p, M, first, drift, second)
    elif kind == ACCELERATION_BOUND:
        acceleration_bound_rows(table, item, p, M, first, drift, second)
    elif kind == TANGENTIAL_FORCE:
        tangential_force_rows(table, item, p, M, first, drift, second)
    elif kind == AXLE_ACCELERATION:
        axle_acceleration_rows(table, item, p, M, first, drift, second)
    elif kind == OBJECT_BALANCE:
        object_balance_rows(table, item, p, M, first, drift, second)
    elif kind == HAND_PAIR:
        hand_pair_rows(table, item, p, M, first, drift, second)
    else:
        raise ValueError("a compiled item of an unknown kind")
