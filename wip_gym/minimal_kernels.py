"""The arithmetic of ``RobotModel.update`` after its MuJoCo calls, compiled by numba.

Four functions that write into the caller's buffers and :func:`all_finite` (the update's input
check); :func:`update_kinematics` and :func:`update_dynamics` run them on the update's arrays,
declared once as :data:`UPDATE` (``wip_gym.array_table``), after MuJoCo's calls: on the fast
path :func:`robot_update_at` makes those calls from compiled code (``wip_gym.mujoco_c``) and
the whole update is one compiled call; on the readable path ``RobotModel`` makes them through
MuJoCo's Python bindings, with the same results to the bit:

* :func:`idealised_state`: the inverse, MuJoCo's ``qpos``, ``qvel`` of a minimal state with the
  wheels on the floor (``RobotModel.full_state``);
* :func:`minimal_state`: the minimal coordinates ``q``, ``nu`` from MuJoCo's ``qpos``, ``qvel``
  and the base's rotation, and the state-dependent entries of ``J_tf`` and ``Jdot_tf nu``;
* :func:`minimal_dynamics_into`: paper eq. ``dyn``, ``A = J_tf^T M J_tf``,
  ``h = J_tf^T (M Jdot_tf nu + c - f_passive)``, ``B = J_tf^T S``;
* :func:`body_com_into`: the body's CoM (wheels excluded) in the axle frame, its Jacobian over
  ``nu``, ``theta = atan2(X, Z)`` and ``J_theta``, ``thetad = J_theta nu``.

and, outside the update, :func:`wipm_values`: the WIPM's parameters ``lambda(q)`` (paper section
"Simplified Model") at the updated state, in one compiled call
(``RobotModel.wipm_values``, once per MPC step), with :func:`inertia_about_point`, on the
arrays of :data:`WIPM` (no MuJoCo call: the same on both paths).

The NumPy expressions they replace are kept in ``tests/test_robot_model.py`` and compared on
random states of every robot (the minimal coordinates also against ``RobotModel.full_state``,
their inverse); :func:`wipm_values` with ``params_from_lambda(RobotModel.wipm_parameters())``,
the path it replaces in the controllers, in ``tests/test_wipm.py``.
"""

from __future__ import annotations

import math
from collections import namedtuple
from typing import Any

import numpy as np
from numba import njit

from wip_gym import mujoco_c as mjc
from wip_gym.array_table import (
    FLOAT_CUBE,
    FLOAT_MATRIX,
    FLOAT_VECTOR,
    INT_MATRIX,
    INT_VECTOR,
    TableSpec,
    float_cube,
    float_matrix,
    float_vector,
    int_matrix,
    int_vector,
)
from wip_gym.small_linalg import small_matmul


@njit(cache=True)
def all_finite(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether every entry of the 1-D arrays ``a`` and ``b`` is finite (one compiled call for
    the four NumPy calls of ``isfinite(a).all() and isfinite(b).all()``)."""
    finite = True
    for i in range(len(a)):
        finite = finite and math.isfinite(a[i])
    for i in range(len(b)):
        finite = finite and math.isfinite(b[i])
    return finite


@njit(cache=True)
def idealised_state(
    q: np.ndarray,
    nu: np.ndarray,
    axle_x: float,
    axle_y: float,
    layout: np.ndarray,
    body_qpos: np.ndarray,
    body_dof: np.ndarray,
    wheel_radius: float,
    wheel_separation: float,
    qpos: np.ndarray,
    qvel: np.ndarray,
) -> None:
    """``RobotModel.full_state`` into ``qpos``, ``qvel`` (every entry of the robot's joints
    written): the wheels on the floor, the axle at the wheel radius and level, in 3-D the axle
    midpoint at ``(axle_x, axle_y)``; the wheel angles split so that ``x`` is their odometry.
    ``layout`` as :func:`minimal_state`'s."""
    planar, o, v = layout[0], layout[1], layout[2]
    wl, wr, dl, dr = layout[3], layout[4], layout[5], layout[6]
    r = wheel_radius
    first = 2 if planar else 3
    for k in range(len(body_qpos)):
        qpos[body_qpos[k]] = q[first + k]
        qvel[body_dof[k]] = nu[first + k]
    x, q1 = q[0], q[first - 1]
    xd, q1d = nu[0], nu[first - 1]
    if planar:
        qpos[o], qpos[o + 1], qpos[o + 2] = x, r, q1
        qpos[wl] = qpos[wr] = x / r - q1
        qvel[v], qvel[v + 1], qvel[v + 2] = xd, 0.0, q1d
        qvel[dl] = qvel[dr] = xd / r - q1d
        return
    psi, psid = q[1], nu[1]
    qpos[o], qpos[o + 1], qpos[o + 2] = axle_x, axle_y, r
    # yaw (cos, 0, 0, sin)(psi / 2) times pitch (cos, 0, sin, 0)(q1 / 2), written out
    cy, sy = math.cos(psi / 2), math.sin(psi / 2)
    cp, sp = math.cos(q1 / 2), math.sin(q1 / 2)
    qpos[o + 3], qpos[o + 4], qpos[o + 5], qpos[o + 6] = cy * cp, -(sy * sp), cy * sp, sy * cp
    half = wheel_separation / (2.0 * r)
    qpos[wl] = x / r - half * psi - q1
    qpos[wr] = x / r + half * psi - q1
    c, s = math.cos(psi), math.sin(psi)
    qvel[v], qvel[v + 1], qvel[v + 2] = xd * c, xd * s, 0.0
    qvel[v + 3], qvel[v + 4], qvel[v + 5] = -psid * math.sin(q1), q1d, psid * math.cos(q1)
    qvel[dl] = xd / r - half * psid - q1d
    qvel[dr] = xd / r + half * psid - q1d


FREE_JOINT_TF_ENTRIES = ((0, 0), (1, 0), (3, 1), (5, 1))
"""The entries of ``J_tf`` that :func:`minimal_state` writes at each state in 3-D, as (row after
the free joint's first dof, column): its linear x, y rows in column ``x`` (``cos psi``, ``sin
psi``), its angular x, z rows in column ``psi`` (``-sin q1``, ``cos q1``)."""


@njit(cache=True)
def minimal_state(
    qpos: np.ndarray,
    qvel: np.ndarray,
    base_xmat: np.ndarray,
    layout: np.ndarray,
    body_qpos: np.ndarray,
    body_dof: np.ndarray,
    wheel_radius: float,
    q: np.ndarray,
    nu: np.ndarray,
    J: np.ndarray,
    Jdot_nu: np.ndarray,
) -> tuple[float, float, float, float]:
    """Fill ``q``, ``nu`` (``wip_gym.robot_model``'s minimal coordinates) and, in 3-D, the
    entries of ``J_tf`` and ``Jdot_tf nu`` that depend on ``psi`` and ``q1``; return ``(psi,
    psid, cos psi, sin psi)``. ``layout``: ``planar, root_qpos, root_dof, wheel_qpos[0],
    wheel_qpos[1], wheel_dof[0], wheel_dof[1]``.

    3-D: ``psi = atan2(-R01, R11)``, ``q1 = atan2(c R02 + s R12, R22)`` (base rotation ``R``);
    the base's world angular velocity ``omega = R w`` gives ``psid = omega_z`` and
    ``q1d = -s omega_x + c omega_y``; ``x = r (phi_L + phi_R) / 2 + r q1`` (odometry of the
    absolute wheel angles) and its rate likewise."""
    planar, o, v = layout[0], layout[1], layout[2]
    wl, wr, dl, dr = layout[3], layout[4], layout[5], layout[6]
    r = wheel_radius
    if planar:
        psi, psid, c, s = 0.0, 0.0, 1.0, 0.0
        q[0], q[1] = qpos[o], qpos[o + 2]
        nu[0], nu[1] = qvel[v], qvel[v + 2]
        first = 2
    else:
        R = base_xmat
        psi = math.atan2(-R[1], R[4])
        c, s = math.cos(psi), math.sin(psi)
        q1 = math.atan2(c * R[2] + s * R[5], R[8])
        w0, w1, w2 = qvel[v + 3], qvel[v + 4], qvel[v + 5]
        omega_x = R[0] * w0 + R[1] * w1 + R[2] * w2
        omega_y = R[3] * w0 + R[4] * w1 + R[5] * w2
        psid = R[6] * w0 + R[7] * w1 + R[8] * w2
        q1d = -s * omega_x + c * omega_y
        xd = r * 0.5 * (qvel[dl] + qvel[dr]) + r * q1d
        q[0] = r * 0.5 * (qpos[wl] + qpos[wr]) + r * q1
        q[1], q[2] = psi, q1
        nu[0], nu[1], nu[2] = xd, psid, q1d
        first = 3
        # J_tf's free-joint rows: the axle's linear velocity in world, the base's angular
        # velocity in its own frame (FREE_JOINT_TF_ENTRIES); and their time derivative along nu
        c1, s1 = math.cos(q1), math.sin(q1)
        J[v + 0, 0] = c
        J[v + 1, 0] = s
        J[v + 3, 1] = -s1
        J[v + 5, 1] = c1
        Jdot_nu[v + 0] = -s * psid * xd
        Jdot_nu[v + 1] = c * psid * xd
        Jdot_nu[v + 3] = -c1 * q1d * psid
        Jdot_nu[v + 5] = -s1 * q1d * psid
    for k in range(len(body_qpos)):
        q[first + k] = qpos[body_qpos[k]]
        nu[first + k] = qvel[body_dof[k]]
    return psi, psid, c, s


@njit(cache=True)
def minimal_dynamics_into(
    M: np.ndarray,
    J: np.ndarray,
    J_pattern: np.ndarray,
    Jdot_nu: np.ndarray,
    bias: np.ndarray,
    passive: np.ndarray,
    S: np.ndarray,
    A_out: np.ndarray,
    h_out: np.ndarray,
    B_out: np.ndarray,
) -> None:
    """``A``, ``h``, ``B`` of paper eq. ``dyn`` into ``A_out``, ``h_out``, ``B_out``, the
    products with ``J = J_tf`` over its nonzero pattern ``J_pattern``
    (``RobotModel.J_tf_pattern``). ``M J`` is made transposed, as the rows of ``J^T M`` (``M``
    is symmetric: MuJoCo's full mass matrix, whose entries ``mj_fullM`` mirrors), so that every
    loop but ``A``'s (which reads a column of ``J^T M``) reads and writes rows; and ``M Jdot_tf
    nu`` visits the nonzero entries of ``Jdot_tf nu`` only (four in 3-D, the free joint's;
    none planar). Each sum adds the same nonzero terms in the same order as ``small_linalg``'s
    ``matmul_pattern``, ``matmul_transposed_pattern`` and ``small_matvec`` would: the terms
    skipped are ``M[i, k] * 0``, which leave a sum that starts at ``+0.0`` unchanged when ``M``
    is finite (tested: equal to the bit)."""
    nv, n = J.shape
    JtM = np.zeros((n, nv))
    for e in range(J_pattern.shape[1]):
        r, c = J_pattern[0, e], J_pattern[1, e]
        value = J[r, c]
        for i in range(nv):
            JtM[c, i] += value * M[r, i]
    A_out[:] = 0.0
    for e in range(J_pattern.shape[1]):
        r, c = J_pattern[0, e], J_pattern[1, e]
        value = J[r, c]
        for j in range(n):
            A_out[c, j] += value * JtM[j, r]
    # M Jdot_tf nu + c - f_passive (the nonzero entries of Jdot_tf nu, rows of M)
    y = np.zeros(nv)
    for k in range(nv):
        d = Jdot_nu[k]
        if d != 0.0:
            for i in range(nv):
                y[i] += M[k, i] * d
    for i in range(nv):
        y[i] = y[i] + bias[i] - passive[i]
    h_out[:] = 0.0
    B_out[:] = 0.0
    for e in range(J_pattern.shape[1]):
        r, c = J_pattern[0, e], J_pattern[1, e]
        value = J[r, c]
        h_out[c] += value * y[r]
        for j in range(S.shape[1]):
            B_out[c, j] += value * S[r, j]


@njit(cache=True)
def body_com_into(
    body_mass: np.ndarray,
    xipos: np.ndarray,
    body_ids: np.ndarray,
    origin: np.ndarray,
    jac_subtree: np.ndarray,
    subtree_mass: float,
    wheels: np.ndarray,
    jac_wheels: np.ndarray,
    jac_origin: np.ndarray,
    J: np.ndarray,
    J_pattern: np.ndarray,
    nu: np.ndarray,
    c: float,
    s: float,
    planar: bool,
    com_out: np.ndarray,
    J_com_out: np.ndarray,
    J_theta_out: np.ndarray,
) -> tuple[float, float, float]:
    """The body's (every robot body but the wheels: ``body_ids``, their masses and CoMs
    ``xipos`` in world) CoM about the axle ``origin`` in the axle frame (``Rz(psi)``, ``c``,
    ``s``; the world's when planar) into ``com_out``, its Jacobian over ``nu`` into
    ``J_com_out`` (the base subtree's CoM Jacobian less the ``wheels``', relative to the
    origin's, times ``J``, nonzero only in ``J_pattern``; in 3-D the frame's turning adds
    ``-psid e_z x com`` in column 1, ``psi``) and ``J_theta`` into ``J_theta_out``; returns
    ``(mass, theta, thetad)``. ``wheels``: the two wheel bodies (left, right), whose CoM
    Jacobians are ``jac_wheels``."""
    mass = 0.0
    for i in range(len(body_ids)):
        mass += body_mass[body_ids[i]]
    w0 = w1 = w2 = 0.0
    for i in range(len(body_ids)):
        b, m = body_ids[i], body_mass[body_ids[i]]
        w0 += m * xipos[b, 0]
        w1 += m * xipos[b, 1]
        w2 += m * xipos[b, 2]
    d0, d1, d2 = w0 / mass - origin[0], w1 / mass - origin[1], w2 / mass - origin[2]
    m_l, m_r = body_mass[wheels[0]], body_mass[wheels[1]]
    nv = jac_subtree.shape[1]
    rel = np.empty((3, nv))
    for a in range(3):
        for k in range(nv):
            value = jac_subtree[a, k] * subtree_mass
            value -= m_l * jac_wheels[0, a, k]
            value -= m_r * jac_wheels[1, a, k]
            rel[a, k] = value / mass - jac_origin[a, k]
    J_com_out[:] = 0.0
    for e in range(J_pattern.shape[1]):
        r, col = J_pattern[0, e], J_pattern[1, e]
        value = J[r, col]
        for a in range(3):
            J_com_out[a, col] += rel[a, r] * value
    if planar:
        com_out[0], com_out[1], com_out[2] = d0, d1, d2
    else:
        com_out[0], com_out[1], com_out[2] = c * d0 + s * d1, -s * d0 + c * d1, d2
        for k in range(J_com_out.shape[1]):
            a0, a1 = J_com_out[0, k], J_com_out[1, k]
            J_com_out[0, k] = c * a0 + s * a1
            J_com_out[1, k] = -s * a0 + c * a1
        J_com_out[0, 1] += com_out[1]
        J_com_out[1, 1] -= com_out[0]
    X, Z = com_out[0], com_out[2]
    theta = math.atan2(X, Z)
    distance_sq = X * X + Z * Z
    thetad = 0.0
    for k in range(J_theta_out.shape[0]):
        if distance_sq > 1e-18:
            J_theta_out[k] = (Z * J_com_out[0, k] - X * J_com_out[2, k]) / distance_sq
        else:
            J_theta_out[k] = 0.0
        thetad += J_theta_out[k] * nu[k]
    return mass, theta, thetad


@njit(cache=True)
def inertia_about_point(
    ximat: np.ndarray,
    xipos: np.ndarray,
    body_inertia: np.ndarray,
    body_mass: np.ndarray,
    ids: np.ndarray,
    point: np.ndarray,
    heading: np.ndarray,
) -> np.ndarray:
    """The inertia tensor of the bodies ``ids`` about ``point``, in the frame ``heading``
    (world from frame): ``sum_i Rh^T R_i diag(I_i) R_i^T Rh + m_i (|p_i|^2 1 - p_i p_i^T)``
    with ``p_i = Rh^T (c_i - point)`` (``RobotModel.body_inertia_about_axle``). Written as
    loops into two scratch arrays: a BLAS product, a matrix-vector product and two new arrays
    per body cost about 0.7 us a body (Krang's 18 bodies: medians of 16 us against 3.6 us,
    side by side on this shared 2-core machine, 2026-11-26)."""
    out = np.zeros((3, 3))
    rot = np.empty((3, 3))
    p = np.empty(3)
    for n in range(len(ids)):
        i = ids[n]
        for a in range(3):  # rot = Rh^T R_i (ximat: R_i row-major)
            for b in range(3):
                total = 0.0
                for k in range(3):
                    total += heading[k, a] * ximat[i, 3 * k + b]
                rot[a, b] = total
        for a in range(3):
            for b in range(3):
                total = 0.0
                for k in range(3):
                    total += rot[a, k] * body_inertia[i, k] * rot[b, k]
                out[a, b] += total
        for a in range(3):
            total = 0.0
            for k in range(3):
                total += heading[k, a] * (xipos[i, k] - point[k])
            p[a] = total
        square = p[0] * p[0] + p[1] * p[1] + p[2] * p[2]
        m = body_mass[i]
        for a in range(3):
            for b in range(3):
                out[a, b] += m * ((square if a == b else 0.0) - p[a] * p[b])
    return out


WIPM = TableSpec(
    "wipm",
    (
        ("ids", INT_VECTOR),  # the base body, the left wheel body, its dof
        ("ximat", FLOAT_MATRIX),
        ("xipos", FLOAT_MATRIX),
        ("xpos", FLOAT_MATRIX),
        ("body_inertia", FLOAT_MATRIX),
        ("wheel_frame", FLOAT_VECTOR),  # the wheel's inertial frame, row-major (mju_quat2Mat)
        ("body_mass", FLOAT_VECTOR),
        ("dof_damping", FLOAT_VECTOR),
        ("gravity", FLOAT_VECTOR),
        ("body_ids", INT_VECTOR),  # the body's bodies: the robot's but the wheels
    ),
)
"""The arrays of :func:`wipm_values` (``RobotModel`` makes its table once per MjModel/MjData):
MuJoCo's arrays, the ids it reads and the wheel's inertial frame, which the caller writes before
each call (``mju_quat2Mat`` of the wheel's ``body_iquat``)."""
_W = WIPM.index


@njit(cache=True)
def wipm_values(
    table: np.ndarray,
    heading: np.ndarray,
    com: np.ndarray,
    body_mass: float,
    theta: float,
    wheel_radius: float,
    wheel_separation: float,
) -> tuple[tuple[float, ...], np.ndarray]:
    """``lambda(q)`` as the WIPM takes it (paper section "Simplified Model";
    ``controllers.simplified.wipm.params_from_lambda`` of ``RobotModel.wipm_parameters``) in one
    compiled call, from MuJoCo's arrays in ``table`` (:data:`WIPM`; read at this call: a
    mass or inertia changed in the model since the last update is seen, as by
    ``wipm_parameters``) and the body's ``com`` (axle frame), ``body_mass`` and ``theta`` of the
    last update.

    Returns ``(values, inertia_body)``: ``values`` = ``(M, L, com_y, m_w, I_a, I_t, d, R, sep,
    g)`` (``wip_gym.robot_model.WIPM_SCALARS``; a tuple of floats: boxing it costs less than
    an array and the scalars taken out of it), with ``L = hypot(X_com, Z_com)``, one wheel's
    mass, axial and transverse inertia ``(Rw diag(I_w) Rw^T)[1, 1]`` and ``[0, 0]`` (``Rw`` the
    wheel's inertial frame, ``table``'s ``wheel_frame``), its joint's damping
    and ``g = -gravity_z``; ``inertia_body`` = ``I_B = Ry(theta)^T I_axle Ry(theta)``,
    symmetrised, with ``I_axle`` the body's inertia about the axle midpoint in the axle frame
    (:func:`inertia_about_point`)."""
    ids = int_vector(table[_W.ids])
    base, wheel, wheel_dof = ids[0], ids[1], ids[2]
    ximat, xipos = float_matrix(table[_W.ximat]), float_matrix(table[_W.xipos])
    xpos, inertia = float_matrix(table[_W.xpos]), float_matrix(table[_W.body_inertia])
    mass, damping = float_vector(table[_W.body_mass]), float_vector(table[_W.dof_damping])
    gravity, bodies = float_vector(table[_W.gravity]), int_vector(table[_W.body_ids])
    frame = float_vector(table[_W.wheel_frame])
    axle = inertia_about_point(ximat, xipos, inertia, mass, bodies, xpos[base], heading)
    # Ry(theta)^T I_axle Ry(theta) (small_matmul: every product, zeros too)
    c, s = math.cos(theta), math.sin(theta)
    rot = np.zeros((3, 3))
    rot[0, 0], rot[0, 2], rot[1, 1], rot[2, 0], rot[2, 2] = c, s, 1.0, -s, c
    rotated = small_matmul(small_matmul(rot.T, axle), rot)
    inertia_body = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            inertia_body[a, b] = 0.5 * (rotated[a, b] + rotated[b, a])
    # one wheel: its principal inertia turned into its body frame (hinge about y)
    axial, transverse = 0.0, 0.0
    for k in range(3):
        axial += frame[3 + k] * inertia[wheel, k] * frame[3 + k]
        transverse += frame[k] * inertia[wheel, k] * frame[k]
    values = (
        body_mass,
        math.hypot(com[0], com[2]),
        com[1],
        mass[wheel],
        axial,
        transverse,
        damping[wheel_dof],
        wheel_radius,
        wheel_separation,
        -gravity[2],
    )
    return values, inertia_body


WIPM_VECTOR_SIZES = (1, 1, 1, 9, 1, 1, 1, 1, 1, 1, 1)
"""The entries of ``lambda(q)`` in :func:`wipm_inputs_into`'s vector, one per field of
``controllers.simplified.wipm.WIPMParams`` in its order (``inertia_body`` row-major): the
order in which the MPC packs its inputs (``controllers.high_level.mpc.param_values``)."""
WIPM_VECTOR_LENGTH = sum(WIPM_VECTOR_SIZES)


@njit(cache=True, nogil=True)
def wipm_inputs_into(
    out: np.ndarray,
    planar: bool,
    scalars: np.ndarray,
    table: np.ndarray,
    com: np.ndarray,
    wheel_radius: float,
    wheel_separation: float,
) -> None:
    """The WIPM state and ``lambda(q)`` of the last update in one vector ``out``: the state
    (planar ``[theta, thetad, x, xd]``, 3-D ``[x, psi, theta, xd, psid, thetad, X0, Y0]``, from
    the update's ``scalars``, :data:`UPDATE_SCALARS`), then :func:`wipm_values`' ``lambda(q)``
    at the heading ``Rz(psi)`` of those scalars, in :data:`WIPM_VECTOR_SIZES`' order. What the
    MPC reads at each of its steps, in one call (``RobotModel.wipm_inputs``)."""
    c, s = scalars[_COS_PSI], scalars[_SIN_PSI]
    heading = np.zeros((3, 3))
    heading[0, 0], heading[0, 1], heading[1, 0], heading[1, 1], heading[2, 2] = c, -s, s, c, 1.0
    values, inertia_body = wipm_values(
        table, heading, com, scalars[_BODY_MASS], scalars[_THETA], wheel_radius, wheel_separation
    )
    if planar:
        n = len(PLANAR_STATE_SCALARS)
        for k in range(n):
            out[k] = scalars[PLANAR_STATE_SCALARS[k]]
    else:
        n = len(SPATIAL_STATE_SCALARS)
        for k in range(n):
            out[k] = scalars[SPATIAL_STATE_SCALARS[k]]
    out[n], out[n + 1], out[n + 2] = values[0], values[1], values[2]
    for a in range(3):
        for b in range(3):
            out[n + 3 + 3 * a + b] = inertia_body[a, b]
    for k in range(3, 10):
        out[n + 9 + k] = values[k]


UPDATE = TableSpec(
    "robot_update",
    (
        ("mujoco", INT_VECTOR),  # the model's and data's addresses (the fast path's)
        ("constants", FLOAT_VECTOR),  # the wheel radius
        ("qpos", FLOAT_VECTOR),  # the state, the robot's own entries
        ("qvel", FLOAT_VECTOR),
        ("data_qpos", FLOAT_VECTOR),  # MuJoCo's arrays
        ("data_qvel", FLOAT_VECTOR),
        ("xmat", FLOAT_MATRIX),
        ("xpos", FLOAT_MATRIX),
        ("xipos", FLOAT_MATRIX),
        ("qfrc_passive", FLOAT_VECTOR),
        ("body_mass", FLOAT_VECTOR),
        ("subtree_mass", FLOAT_VECTOR),
        ("bodies", INT_VECTOR),  # base, left wheel, right wheel
        ("body_ids", INT_VECTOR),  # the body's bodies: the robot's but the wheels
        ("layout", INT_VECTOR),  # as minimal_state takes them
        ("body_qpos", INT_VECTOR),
        ("body_dof", INT_VECTOR),
        ("q", FLOAT_VECTOR),  # the update's outputs and scratch
        ("nu", FLOAT_VECTOR),
        ("J", FLOAT_MATRIX),
        ("J_pattern", INT_MATRIX),
        ("Jdot_nu", FLOAT_VECTOR),
        ("jac_subtree", FLOAT_MATRIX),
        ("jac_wheels", FLOAT_CUBE),
        ("jac_origin", FLOAT_MATRIX),
        ("M", FLOAT_MATRIX),
        ("bias", FLOAT_VECTOR),
        ("S", FLOAT_MATRIX),
        ("scalars", FLOAT_VECTOR),
        ("com", FLOAT_VECTOR),
        ("J_com", FLOAT_MATRIX),
        ("J_theta", FLOAT_VECTOR),
        ("A", FLOAT_MATRIX),
        ("h", FLOAT_VECTOR),
        ("B", FLOAT_MATRIX),
    ),
)
"""The arrays of ``RobotModel.update`` (``RobotModel`` builds the table once per MuJoCo data):
its MuJoCo calls are :func:`robot_update_at`'s on the fast path, the bindings' on the readable
one, and both run :func:`update_kinematics` and :func:`update_dynamics` on this table."""
_U = UPDATE.index

UPDATE_SCALARS = (
    "psi",
    "psid",
    "cos_psi",
    "sin_psi",
    "body_mass",
    "theta",
    "thetad",
    "x",
    "xd",
    "axle_x",
    "axle_y",
)
"""The entries of the update's ``scalars``, in order (``x``, ``xd``: the first minimal
coordinate and its rate; ``axle_x``, ``axle_y``: the base origin's world position)."""
SCALAR: Any = namedtuple("UpdateScalar", UPDATE_SCALARS)(*range(len(UPDATE_SCALARS)))
"""Each scalar's index in ``scalars`` (compiled code reads ``scalars[SCALAR.theta]``)."""
_COS_PSI, _SIN_PSI, _BODY_MASS, _THETA = (
    SCALAR.cos_psi,
    SCALAR.sin_psi,
    SCALAR.body_mass,
    SCALAR.theta,
)
#: the WIPM state (``RobotModel.wipm_state``) as indices into :data:`UPDATE_SCALARS`: planar
#: ``[theta, thetad, x, xd]``, 3-D ``[x, psi, theta, xd, psid, thetad, X0, Y0]``
PLANAR_STATE_SCALARS = tuple(UPDATE_SCALARS.index(name) for name in ("theta", "thetad", "x", "xd"))
SPATIAL_STATE_SCALARS = tuple(
    UPDATE_SCALARS.index(name)
    for name in ("x", "psi", "theta", "xd", "psid", "thetad", "axle_x", "axle_y")
)


@njit(cache=True)
def update_kinematics(table: np.ndarray) -> None:
    """``RobotModel.update``'s arithmetic after MuJoCo's kinematics, ``mj_comPos``, the base
    subtree's CoM Jacobian and the Jacobians of the wheels' CoMs and of the base origin (the
    arrays of ``table``, :data:`UPDATE`): :func:`minimal_state`, :func:`body_com_into` and
    ``(psi, psid, cos psi, sin psi, mass, theta, thetad, x, xd, axle_x, axle_y)`` into
    ``scalars`` (:data:`UPDATE_SCALARS`)."""
    bodies, xpos = int_vector(table[_U.bodies]), float_matrix(table[_U.xpos])
    layout, nu = int_vector(table[_U.layout]), float_vector(table[_U.nu])
    q, J = float_vector(table[_U.q]), float_matrix(table[_U.J])
    base = bodies[0]
    psi, psid, c, s = minimal_state(
        float_vector(table[_U.data_qpos]),
        float_vector(table[_U.data_qvel]),
        float_matrix(table[_U.xmat])[base],
        layout,
        int_vector(table[_U.body_qpos]),
        int_vector(table[_U.body_dof]),
        float_vector(table[_U.constants])[0],
        q,
        nu,
        J,
        float_vector(table[_U.Jdot_nu]),
    )
    mass, theta, thetad = body_com_into(
        float_vector(table[_U.body_mass]),
        float_matrix(table[_U.xipos]),
        int_vector(table[_U.body_ids]),
        xpos[base],
        float_matrix(table[_U.jac_subtree]),
        float_vector(table[_U.subtree_mass])[base],
        bodies[1:],
        float_cube(table[_U.jac_wheels]),
        float_matrix(table[_U.jac_origin]),
        J,
        int_matrix(table[_U.J_pattern]),
        nu,
        c,
        s,
        layout[0] != 0,
        float_vector(table[_U.com]),
        float_matrix(table[_U.J_com]),
        float_vector(table[_U.J_theta]),
    )
    scalars = float_vector(table[_U.scalars])
    scalars[SCALAR.psi], scalars[SCALAR.psid] = psi, psid
    scalars[SCALAR.cos_psi], scalars[SCALAR.sin_psi] = c, s
    scalars[SCALAR.body_mass], scalars[SCALAR.theta], scalars[SCALAR.thetad] = mass, theta, thetad
    scalars[SCALAR.x], scalars[SCALAR.xd] = q[0], nu[0]
    scalars[SCALAR.axle_x], scalars[SCALAR.axle_y] = xpos[base, 0], xpos[base, 1]


@njit(cache=True)
def update_dynamics(table: np.ndarray) -> None:
    """``RobotModel.update``'s arithmetic after MuJoCo's ``mj_crb``, full mass matrix (into
    ``M``), ``mj_comVel``, ``mj_passive`` and ``mj_rne`` (into ``bias``): paper eq. ``dyn``,
    :func:`minimal_dynamics_into`, on the arrays of ``table`` (:data:`UPDATE`)."""
    minimal_dynamics_into(
        float_matrix(table[_U.M]),
        float_matrix(table[_U.J]),
        int_matrix(table[_U.J_pattern]),
        float_vector(table[_U.Jdot_nu]),
        float_vector(table[_U.bias]),
        float_vector(table[_U.qfrc_passive]),
        float_matrix(table[_U.S]),
        float_matrix(table[_U.A]),
        float_vector(table[_U.h]),
        float_matrix(table[_U.B]),
    )


@njit(cache=True, nogil=True)
def robot_update_at(table: np.ndarray, dynamics: bool) -> bool:
    """``RobotModel.update`` on the fast path, in one compiled call on the arrays of ``table``
    (:data:`UPDATE`): first :func:`all_finite` on the state (``qpos``, ``qvel``; False, with
    nothing computed or written, if it is not), then the state into MuJoCo's data, its
    kinematics and ``mj_comPos``, the Jacobians of the base subtree's CoM, of the wheels' CoMs
    and of the base origin, :func:`update_kinematics`; with ``dynamics`` also ``mj_crb``, the
    full mass matrix, ``mj_comVel``, ``mj_passive``, ``mj_rne`` and :func:`update_dynamics`
    (else ``A``, ``h``, ``B`` are left as they are). MuJoCo's functions are called through
    ``wip_gym.mujoco_c``."""
    qpos, qvel = float_vector(table[_U.qpos]), float_vector(table[_U.qvel])
    if not all_finite(qpos, qvel):
        return False
    addresses = int_vector(table[_U.mujoco])
    model, data = addresses[0], addresses[1]
    float_vector(table[_U.data_qpos])[: len(qpos)] = qpos
    float_vector(table[_U.data_qvel])[: len(qvel)] = qvel
    mjc.mj_kinematics(model, data)
    mjc.mj_comPos(model, data)
    bodies = int_vector(table[_U.bodies])
    xpos, xipos = float_matrix(table[_U.xpos]), float_matrix(table[_U.xipos])
    jac_wheels = float_cube(table[_U.jac_wheels])
    base = bodies[0]
    mjc.mj_jacSubtreeCom(model, data, float_matrix(table[_U.jac_subtree]).ctypes.data, base)
    for k in range(2):
        wheel = bodies[1 + k]
        mjc.mj_jac(model, data, jac_wheels[k].ctypes.data, 0, xipos[wheel].ctypes.data, wheel)
    jac_origin = float_matrix(table[_U.jac_origin])
    mjc.mj_jac(model, data, jac_origin.ctypes.data, 0, xpos[base].ctypes.data, base)
    update_kinematics(table)
    if dynamics:
        mjc.mj_crb(model, data)
        mjc.mj_fullM(model, data, float_matrix(table[_U.M]).ctypes.data)
        mjc.mj_comVel(model, data)
        mjc.mj_passive(model, data)
        mjc.mj_rne(model, data, 0, float_vector(table[_U.bias]).ctypes.data)
        update_dynamics(table)
    return True
