"""The arithmetic of ``WIPEnv.step`` around its MuJoCo calls, compiled by numba: the env's
fast path.

``WIPEnv._measure`` makes one call of :func:`env_measures`, which runs MuJoCo's kinematics and
subtree passes on the env's data, reads its contacts through addresses taken once per MjData
(``mujoco_c.contact_layout``; the count is ``data.ncon``, passed in) and then
:func:`step_measures`, which computes, from the data's arrays, every number of the step's
observation, reward and info into a preallocated float vector (:data:`OUT`): the robot's
measures (``psi``, ``x``, ``theta`` ... of ``RobotModel``), the goal distance, the fall, the
end effector's drift, and on a tray task the cup's pose in the tray frame and its state, the
tray's place on the hand and the cup's friction use on the plate. Its readable definition, in
plain Python floats through MuJoCo's bindings, is ``wip_gym.envs.step_reference.measures``:
the env's readable path, which ``tests/test_env_step_reference.py`` holds this one to, step by
step.

The integer parameters (``ints``, :data:`INT`) are the model's ids and addresses followed by
one entry per geom (``GEOM_*`` bits: a robot body geom whose floor contact is a fall, a cup
geom); the float parameters (``floats``, :data:`FLOAT`) are the task's constants. Each
vector's layout is declared once (``wip_gym.array_table.field_offsets``).
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np
from numba import carray, njit, types

from wip_gym import mujoco_c as mjc
from wip_gym.array_table import (
    FLOAT_MATRIX,
    FLOAT_VECTOR,
    INT_VECTOR,
    ArrayTable,
    TableSpec,
    field_offsets,
    float64_view,
    float_matrix,
    float_vector,
    int32_pointer,
    int_vector,
)
from wip_gym.mujoco_c import contact_layout
from wip_gym.scene import CUP_HALF_HEIGHT, CUP_RADIUS, TRAY_HALF_SIZE

#: a cup counts as upright while its axis is within this angle of the tray's normal (deg)
CUP_UPRIGHT_DEG = 30.0
#: a cup counts as on the plate while its lowest point is at most this far above the plate (m)
CUP_PLATE_GAP = 0.005
#: a free tray counts as on the hand while its origin is within this distance of its nominal
#: place along the nominal normal (m), and over the hand (within the plate's half-size)
TRAY_HAND_GAP = 0.01

_HALF_X, _HALF_Y, _HALF_Z = (float(v) for v in TRAY_HALF_SIZE)

INT, N_INTS = field_offsets(
    "int_parameter",
    (
        ("base", 1),
        ("wheel_left", 1),
        ("wheel_right", 1),
        ("planar", 1),
        ("root_qpos", 1),
        ("root_dof", 1),
        ("qpos_left", 1),
        ("qpos_right", 1),
        ("dof_left", 1),
        ("dof_right", 1),
        ("ee_site", 1),  # -1: none
        ("tray", 1),
        ("free_tray", 1),
        ("tray_body", 1),
        ("cup_body", 1),
        ("rest_site", 1),
        ("floor", 1),
        ("tray_geom", 1),
    ),
)
"""The integer parameters: the model's ids and addresses; one entry per geom follows
(``GEOM_*`` bits)."""
GEOM_FALL, GEOM_CUP = 1, 2
"""A geom's bits: a robot body geom whose floor contact is a fall; a cup geom."""

FLOAT, N_FLOATS = field_offsets(
    "float_parameter",
    (("wheel_radius", 1), ("goal", 2), ("fall_angle", 1), ("ee_reference", 3), ("cup_friction", 1)),
)
"""The float parameters: the task's constants."""

OUT, N_OUT = field_offsets(
    "measure",
    (
        ("x", 1),
        ("xd", 1),
        ("theta", 1),
        ("thetad", 1),
        ("psi", 1),
        ("psid", 1),
        ("cos_psi", 1),
        ("sin_psi", 1),
        ("axle", 3),
        ("goal_distance", 1),
        ("fallen", 1),
        ("ee_error", 1),
        ("ee", 3),  # the end effector in the axle frame
        ("cup_pose", 7),  # position in the tray frame, quaternion (w >= 0)
        ("cup_tilt_deg", 1),
        ("cup_upright", 1),
        ("cup_on_plate", 1),
        ("tray_tilt_deg", 1),
        ("tray_offset", 3),
        ("tray_on_hand", 1),
        ("cup_friction_use", 1),
    ),
)
"""The results (flags as 0.0 / 1.0)."""


@njit(cache=True)
def step_measures(
    qpos: np.ndarray,
    qvel: np.ndarray,
    xpos: np.ndarray,
    xmat: np.ndarray,
    xquat: np.ndarray,
    xipos: np.ndarray,
    subtree_com: np.ndarray,
    subtree_linvel: np.ndarray,
    site_xpos: np.ndarray,
    site_xmat: np.ndarray,
    subtree_mass: np.ndarray,
    body_mass: np.ndarray,
    contact_geom: np.ndarray,
    contact_frame: np.ndarray,
    contact_force: np.ndarray,
    ints: np.ndarray,
    floats: np.ndarray,
    out: np.ndarray,
) -> None:
    """Fill ``out`` (``N_OUT`` floats) from the data's arrays after ``mj_kinematics``,
    ``mj_comPos``, ``mj_comVel`` and ``mj_subtreeVel``, and its contacts (``ncon`` rows each:
    ``contact_geom``, the geom pair; ``contact_frame``; ``contact_force``, the first three
    entries of ``mj_contactForce``: normal, tangent 1, tangent 2 in the contact frame, zeros
    for a contact excluded from the constraints).

    Robot: heading ``psi`` (the base's yaw), ``psid``, ``x = r (phi_L + phi_R) / 2 + r q1``,
    ``xd`` (planar: the root slide), the axle (the base origin), and ``theta = atan2(X, Z)``,
    ``thetad`` of the body CoM (the robot's subtree less the wheels, whose CoMs sit on the axle)
    about the axle in the heading frame. Goal distance: of the axle in the plane (planar: along
    x). Fallen: ``|theta| > fall_angle`` or a robot body geom touching the floor. End effector:
    its site in the axle frame and its distance to the float parameters' ``ee_reference``.

    Tray task: the cup's pose in the tray frame (``R_tray^T (p_cup - p_tray)`` and the conjugate
    of the tray's quaternion times the cup's, ``w >= 0``); its tilt (the angle between its axis
    and the tray's normal), upright (tilt <= ``CUP_UPRIGHT_DEG``), on the plate (its centre over
    the plate and above it, its lowest point at most ``CUP_PLATE_GAP`` above the plate's top);
    the tray's tilt (its normal against world z); a free tray's offset from its nominal place
    (the ``tray_rest`` site's frame) and whether it is on the hand (within ``TRAY_HAND_GAP``
    along the normal, within the half-size across); the cup's friction use on the plate
    (``wip_gym.envs.base.friction_use``: the norm of the net tangential force over ``mu`` times
    the net normal force, 0 without contact; either friction cone).
    """
    base, wl, wr = ints[INT.base], ints[INT.wheel_left], ints[INT.wheel_right]
    r = floats[FLOAT.wheel_radius]
    ax, ay, az = xpos[base, 0], xpos[base, 1], xpos[base, 2]
    if ints[INT.planar]:
        c, s, psi, psid = 1.0, 0.0, 0.0, 0.0
        v = ints[INT.root_dof]
        x = qpos[ints[INT.root_qpos]]
        xd, voz, wy_ = qvel[v], qvel[v + 1], qvel[v + 2]
        vox, voy = xd, 0.0
        wx_ = wz_ = 0.0
    else:
        R = xmat[base]
        psi = math.atan2(-R[1], R[4])
        c, s = math.cos(psi), math.sin(psi)
        q1 = math.atan2(c * R[2] + s * R[5], R[8])
        v = ints[INT.root_dof]
        vox, voy, voz = qvel[v], qvel[v + 1], qvel[v + 2]
        w0, w1, w2 = qvel[v + 3], qvel[v + 4], qvel[v + 5]
        wx_ = R[0] * w0 + R[1] * w1 + R[2] * w2
        wy_ = R[3] * w0 + R[4] * w1 + R[5] * w2
        wz_ = psid = R[6] * w0 + R[7] * w1 + R[8] * w2
        q1d = -s * wx_ + c * wy_
        x = r * 0.5 * (qpos[ints[INT.qpos_left]] + qpos[ints[INT.qpos_right]]) + r * q1
        xd = r * 0.5 * (qvel[ints[INT.dof_left]] + qvel[ints[INT.dof_right]]) + r * q1d
    mass = subtree_mass[base]
    ml, mr = body_mass[wl], body_mass[wr]
    body = mass - ml - mr
    cx, cy, cz = subtree_com[base, 0], subtree_com[base, 1], subtree_com[base, 2]
    lx, ly, lz = xipos[wl, 0], xipos[wl, 1], xipos[wl, 2]
    rx, ry, rz = xipos[wr, 0], xipos[wr, 1], xipos[wr, 2]
    vx, vy, vz = subtree_linvel[base, 0], subtree_linvel[base, 1], subtree_linvel[base, 2]
    dx = (mass * cx - ml * lx - mr * rx) / body - ax
    dy = (mass * cy - ml * ly - mr * ry) / body - ay
    dz = (mass * cz - ml * lz - mr * rz) / body - az
    # sum over the wheels of m_w (v_o + omega x (p_w - o)) = (ml + mr) v_o + omega x s_w
    sx = ml * (lx - ax) + mr * (rx - ax)
    sy = ml * (ly - ay) + mr * (ry - ay)
    sz = ml * (lz - az) + mr * (rz - az)
    wheels = ml + mr
    dvx = (mass * vx - wheels * vox - (wy_ * sz - wz_ * sy)) / body - vox
    dvy = (mass * vy - wheels * voy - (wz_ * sx - wx_ * sz)) / body - voy
    dvz = (mass * vz - wheels * voz - (wx_ * sy - wy_ * sx)) / body - voz
    X_, Y_, Z_ = c * dx + s * dy, -s * dx + c * dy, dz
    Xd = c * dvx + s * dvy + psid * Y_
    Zd = dvz
    distance_sq = X_ * X_ + Z_ * Z_
    theta = math.atan2(X_, Z_)
    out[OUT.x], out[OUT.xd], out[OUT.theta] = x, xd, theta
    out[OUT.thetad] = (Z_ * Xd - X_ * Zd) / distance_sq if distance_sq > 1e-18 else 0.0
    out[OUT.psi], out[OUT.psid], out[OUT.cos_psi], out[OUT.sin_psi] = psi, psid, c, s
    out[OUT.axle], out[OUT.axle + 1], out[OUT.axle + 2] = ax, ay, az
    gx, gy = floats[FLOAT.goal], floats[FLOAT.goal + 1]
    if ints[INT.planar]:
        out[OUT.goal_distance] = abs(gx - ax)
    else:
        out[OUT.goal_distance] = math.hypot(gx - ax, gy - ay)

    # the fall: the pitch, or a body geom on the floor
    ncon = contact_geom.shape[0]
    fallen = abs(theta) > floats[FLOAT.fall_angle]
    if not fallen:
        floor = ints[INT.floor]
        for i in range(ncon):
            g1, g2 = contact_geom[i, 0], contact_geom[i, 1]
            if g1 < 0 or g2 < 0:  # a flex's contact, not a pair of geoms
                continue
            if (g1 == floor and ints[N_INTS + g2] & GEOM_FALL) or (
                g2 == floor and ints[N_INTS + g1] & GEOM_FALL
            ):
                fallen = True
                break
    out[OUT.fallen] = 1.0 if fallen else 0.0

    ee = ints[INT.ee_site]
    if ee >= 0:
        ex, ey, ez = site_xpos[ee, 0] - ax, site_xpos[ee, 1] - ay, site_xpos[ee, 2] - az
        ex, ey = c * ex + s * ey, -s * ex + c * ey
        out[OUT.ee], out[OUT.ee + 1], out[OUT.ee + 2] = ex, ey, ez
        ex -= floats[FLOAT.ee_reference]
        ey -= floats[FLOAT.ee_reference + 1]
        ez -= floats[FLOAT.ee_reference + 2]
        out[OUT.ee_error] = math.sqrt(ex * ex + ey * ey + ez * ez)
    if not ints[INT.tray]:
        return

    # the cup's pose in the tray frame
    tray, cup = ints[INT.tray_body], ints[INT.cup_body]
    T = xmat[tray]
    dx, dy, dz = (
        xpos[cup, 0] - xpos[tray, 0],
        xpos[cup, 1] - xpos[tray, 1],
        xpos[cup, 2] - xpos[tray, 2],
    )
    px = T[0] * dx + T[3] * dy + T[6] * dz
    py = T[1] * dx + T[4] * dy + T[7] * dz
    pz = T[2] * dx + T[5] * dy + T[8] * dz
    # the conjugate of the tray's quaternion times the cup's (mju_negQuat, mju_mulQuat)
    a0, a1, a2, a3 = xquat[tray, 0], -xquat[tray, 1], -xquat[tray, 2], -xquat[tray, 3]
    b0, b1, b2, b3 = xquat[cup, 0], xquat[cup, 1], xquat[cup, 2], xquat[cup, 3]
    w = a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3
    qx = a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2
    qy = a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1
    qz = a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0
    if w < 0.0:  # the sign convention of mju_mat2Quat near identity: w >= 0
        w, qx, qy, qz = -w, -qx, -qy, -qz
    pose = OUT.cup_pose
    out[pose], out[pose + 1], out[pose + 2] = px, py, pz
    out[pose + 3], out[pose + 4], out[pose + 5], out[pose + 6] = w, qx, qy, qz

    # its state: R[2, 2] of the quaternion is the cosine of the tilt
    cos_tilt = min(1.0, max(-1.0, 1.0 - 2.0 * (qx * qx + qy * qy)))
    tilt = math.degrees(math.acos(cos_tilt))
    sin_tilt = math.sqrt(max(0.0, 1.0 - cos_tilt * cos_tilt))
    top = 2 * _HALF_Z
    lowest = pz - CUP_HALF_HEIGHT * abs(cos_tilt) - CUP_RADIUS * sin_tilt
    on_plate = (
        abs(px) <= _HALF_X and abs(py) <= _HALF_Y and pz > top and lowest - top <= CUP_PLATE_GAP
    )
    out[OUT.cup_tilt_deg] = tilt
    out[OUT.cup_upright] = 1.0 if tilt <= CUP_UPRIGHT_DEG else 0.0
    out[OUT.cup_on_plate] = 1.0 if on_plate else 0.0
    out[OUT.tray_tilt_deg] = math.degrees(math.acos(min(1.0, max(-1.0, T[8]))))

    # the free tray's place on the hand
    if ints[INT.free_tray]:
        rest = ints[INT.rest_site]
        S = site_xmat[rest]
        dx = xpos[tray, 0] - site_xpos[rest, 0]
        dy = xpos[tray, 1] - site_xpos[rest, 1]
        dz = xpos[tray, 2] - site_xpos[rest, 2]
        ox = S[0] * dx + S[3] * dy + S[6] * dz
        oy = S[1] * dx + S[4] * dy + S[7] * dz
        oz = S[2] * dx + S[5] * dy + S[8] * dz
        on_hand = abs(oz) <= TRAY_HAND_GAP and abs(ox) <= _HALF_X and abs(oy) <= _HALF_Y
    else:
        ox = oy = oz = 0.0
        on_hand = True
    out[OUT.tray_offset], out[OUT.tray_offset + 1], out[OUT.tray_offset + 2] = ox, oy, oz
    out[OUT.tray_on_hand] = 1.0 if on_hand else 0.0

    # the cup's friction use on the plate, from the contact-frame forces
    plate = ints[INT.tray_geom]
    normal = tx = ty = tz = 0.0
    for i in range(ncon):
        g1, g2 = contact_geom[i, 0], contact_geom[i, 1]
        if (
            g1 < 0
            or g2 < 0
            or not (
                (g1 == plate and ints[N_INTS + g2] & GEOM_CUP)
                or (g2 == plate and ints[N_INTS + g1] & GEOM_CUP)
            )
        ):
            continue
        f_n, f_1, f_2 = contact_force[i, 0], contact_force[i, 1], contact_force[i, 2]
        # rows of the contact frame: normal, tangent 1, tangent 2
        F = contact_frame[i]
        normal += f_n
        tx += f_1 * F[3] + f_2 * F[6]
        ty += f_1 * F[4] + f_2 * F[7]
        tz += f_1 * F[5] + f_2 * F[8]
    out[OUT.cup_friction_use] = 0.0
    if normal > 0.0:
        out[OUT.cup_friction_use] = math.sqrt(tx * tx + ty * ty + tz * tz) / (
            floats[FLOAT.cup_friction] * normal
        )


ENV = TableSpec(
    "env_measures",
    (
        # the model's and data's addresses, then where the data's contacts are
        # (mujoco_c.contact_layout: geom, frame, stride, capacity)
        ("mujoco", INT_VECTOR),
        ("qpos", FLOAT_VECTOR),
        ("qvel", FLOAT_VECTOR),
        ("xpos", FLOAT_MATRIX),
        ("xmat", FLOAT_MATRIX),
        ("xquat", FLOAT_MATRIX),
        ("xipos", FLOAT_MATRIX),
        ("subtree_com", FLOAT_MATRIX),
        ("subtree_linvel", FLOAT_MATRIX),
        ("site_xpos", FLOAT_MATRIX),
        ("site_xmat", FLOAT_MATRIX),
        ("subtree_mass", FLOAT_VECTOR),
        ("body_mass", FLOAT_VECTOR),
        ("ints", INT_VECTOR),  # INT, then the geoms' bits
        ("floats", FLOAT_VECTOR),  # FLOAT
        ("out", FLOAT_VECTOR),  # OUT
    ),
)
"""The arrays of :func:`env_measures` (the fast path's env step)."""
_E = ENV.index
_MODEL, _DATA, _GEOM, _FRAME, _STRIDE, _CAPACITY = range(6)  # the "mujoco" entries


def env_table(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    ints: np.ndarray,
    floats: np.ndarray,
    out: np.ndarray,
) -> ArrayTable:
    """The table of :func:`env_measures` (:data:`ENV`): the addresses of ``model`` and
    ``data`` and of the arrays :func:`step_measures` reads (MuJoCo allocates them once per
    MjModel/MjData: the table is valid while both live), the contacts' layout
    (``mujoco_c.contact_layout``), the parameters and the results."""
    layout = (*mjc.addresses(model, data), *contact_layout(data))
    return ENV.table(
        {
            "mujoco": np.array(layout, dtype=np.int64),
            "qpos": data.qpos,
            "qvel": data.qvel,
            "xpos": data.xpos,
            "xmat": data.xmat,
            "xquat": data.xquat,
            "xipos": data.xipos,
            "subtree_com": data.subtree_com,
            "subtree_linvel": data.subtree_linvel,
            "site_xpos": data.site_xpos,
            "site_xmat": data.site_xmat,
            "subtree_mass": model.body_subtreemass,
            "body_mass": model.body_mass,
            "ints": ints,
            "floats": floats,
            "out": out,
        }
    )


@njit(cache=True)
def gather_contacts(
    table: np.ndarray, ncon: int, forces: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first ``ncon`` contacts of the data of ``table`` (:func:`env_table`), read through
    ``mujoco_c.contact_layout``: their geom pairs, frames and, if ``forces``, the first three
    entries of ``mj_contactForce`` (normal, tangent 1, tangent 2 in the contact frame; zeros
    otherwise). Raises if ``ncon`` is more than the arena holds (it must be ``data.ncon``)."""
    layout = int_vector(table[_E.mujoco])
    if ncon < 0 or ncon > layout[_CAPACITY]:
        raise ValueError("ncon must be data.ncon: more contacts than the data's arena holds")
    model, data = np.uint64(layout[_MODEL]), np.uint64(layout[_DATA])
    geom = np.empty((ncon, 2), np.int32)
    frame = np.empty((ncon, 9))
    force = np.zeros((ncon, 3))
    result = np.empty(6)
    stride = layout[_STRIDE]
    for i in range(ncon):
        pair = carray(int32_pointer(np.uint64(layout[_GEOM] + i * stride)), 2)
        geom[i, 0], geom[i, 1] = pair[0], pair[1]
        frame[i] = float64_view(layout[_FRAME] + i * stride, (9,))
        if forces:
            mjc.mj_contactForce(model, data, i, result.ctypes.data)
            force[i, 0], force[i, 1], force[i, 2] = result[0], result[1], result[2]
    return geom, frame, force


@njit(cache=True, nogil=True)
def env_measures(table: np.ndarray, ncon: int) -> None:
    """The env's measures after a step in one compiled call (the fast path): MuJoCo's
    kinematics, ``mj_comPos``, ``mj_comVel`` and ``mj_subtreeVel`` on the data of ``table``
    (:func:`env_table`), its first ``ncon`` (``data.ncon``) contacts (:func:`gather_contacts`;
    their forces only on a tray task, for the cup's friction use), then :func:`step_measures`
    on its arrays, into its ``out``."""
    layout = int_vector(table[_E.mujoco])
    model, data = np.uint64(layout[_MODEL]), np.uint64(layout[_DATA])
    mjc.mj_kinematics(model, data)
    mjc.mj_comPos(model, data)
    mjc.mj_comVel(model, data)  # mj_subtreeVel reads the bodies' velocities (cvel)
    mjc.mj_subtreeVel(model, data)
    ints = int_vector(table[_E.ints])
    geom, frame, force = gather_contacts(table, ncon, ints[INT.tray] != 0)
    step_measures(
        float_vector(table[_E.qpos]),
        float_vector(table[_E.qvel]),
        float_matrix(table[_E.xpos]),
        float_matrix(table[_E.xmat]),
        float_matrix(table[_E.xquat]),
        float_matrix(table[_E.xipos]),
        float_matrix(table[_E.subtree_com]),
        float_matrix(table[_E.subtree_linvel]),
        float_matrix(table[_E.site_xpos]),
        float_matrix(table[_E.site_xmat]),
        float_vector(table[_E.subtree_mass]),
        float_vector(table[_E.body_mass]),
        geom,
        frame,
        force,
        ints,
        float_vector(table[_E.floats]),
        float_vector(table[_E.out]),
    )


@njit(cache=True)
def action_effort(action: np.ndarray, table: np.ndarray) -> float:
    """``sum((action / scale)^2)`` (the ctrl cost's effort) if every torque is within its band
    ``table[0] <= action <= table[1]`` (``scale = table[2]``), else NaN (also for a NaN
    torque); summed in the actuators' order."""
    effort = 0.0
    for i in range(action.shape[0]):
        value = action[i]
        if not table[0, i] <= value <= table[1, i]:
            return math.nan
        value /= table[2, i]
        effort += value * value
    return effort


_F1, _F2 = types.float64[::1], types.float64[:, ::1]
#: the one version: MuJoCo's arrays and the contacts' (gathered by env_measures), contiguous
SIGNATURE = types.void(
    *(_F1, _F1),  # qpos, qvel
    *(_F2,) * 8,  # xpos ... site_xmat
    *(_F1, _F1),  # body_subtreemass, body_mass
    types.int32[:, ::1],  # the contacts' geom pairs, frames and forces
    _F2,
    _F2,
    types.int64[::1],
    _F1,
    _F1,
)


#: the env's version: its table and ``data.ncon``
ENV_SIGNATURE = types.void(types.int64[:, ::1], types.intp)

#: an action of any layout, read-only too (``np.asarray`` of a JAX array)
ACTION_SIGNATURE = types.float64(types.Array(types.float64, 1, "A", readonly=True), _F2)


def compile_once(fast: bool) -> None:
    """Compile :func:`action_effort` for :data:`ACTION_SIGNATURE` and, for the fast path
    (``fast``), :func:`step_measures` for :data:`SIGNATURE` and :func:`env_measures` (or load
    them from numba's cache) and no other versions: a call with arrays of another layout
    converts to them instead of compiling again (once per process; the env calls it when
    made)."""
    kernels: list[tuple[Any, Any]] = [(action_effort, ACTION_SIGNATURE)]
    if fast:
        kernels += [(step_measures, SIGNATURE), (env_measures, ENV_SIGNATURE)]
    for kernel, signature in kernels:
        if not kernel.signatures:
            kernel.compile(signature)
            kernel.disable_compile()
