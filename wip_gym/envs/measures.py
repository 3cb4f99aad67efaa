"""The arithmetic of ``WIPEnv.step`` around its MuJoCo calls, compiled by numba.

``WIPEnv._measure`` makes one call of :func:`env_measures`, which runs MuJoCo's kinematics and
subtree passes on the env's data, reads its contacts through addresses taken once per MjData
(``mujoco_c.contact_layout``; the count is ``data.ncon``, passed in) and then
:func:`step_measures`,
which computes, from the data's arrays, every number of the step's observation, reward and
info into a preallocated float buffer (indices below): the robot's measures (``psi``, ``x``,
``theta`` ... of ``RobotModel``), the goal distance, the fall, the end effector's drift, and on
a tray task the cup's pose in the tray frame and its state, the tray's place on the hand and
the cup's friction use on the plate. The same arithmetic in plain Python floats is kept in
``tests/env_step_reference.py`` and compared step by step with the env
(``tests/test_env_step_reference.py``).

The integer parameters (``ints``) are the model's ids and addresses (``I_*`` below) followed by
one entry per geom (``GEOM_*`` bits: a robot body geom whose floor contact is a fall, a cup
geom); the float parameters (``floats``) are the task's constants (``F_*``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import carray, njit, types

from wip_gym import mujoco_c as mjc
from wip_gym.array_table import float64_view, int32_pointer
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

# the integer parameters
I_BASE, I_WHEEL_L, I_WHEEL_R, I_PLANAR = 0, 1, 2, 3
I_ROOT_QPOS, I_ROOT_DOF, I_QPOS_L, I_QPOS_R, I_DOF_L, I_DOF_R = 4, 5, 6, 7, 8, 9
I_EE_SITE, I_TRAY, I_FREE_TRAY, I_TRAY_BODY, I_CUP_BODY, I_REST_SITE = 10, 11, 12, 13, 14, 15
I_FLOOR, I_TRAY_GEOM = 16, 17
N_INTS = 18  # the geoms' bits follow
GEOM_FALL, GEOM_CUP = 1, 2

# the float parameters
F_WHEEL_RADIUS, F_GOAL_X, F_GOAL_Y, F_FALL_ANGLE = 0, 1, 2, 3
F_EE_REFERENCE = 4  # 3 entries
F_CUP_FRICTION = 7
N_FLOATS = 8

# the results (flags as 0.0 / 1.0)
X, XD, THETA, THETAD, PSI, PSID, COS_PSI, SIN_PSI = 0, 1, 2, 3, 4, 5, 6, 7
AXLE = 8  # 3 entries
GOAL_DISTANCE, FALLEN, EE_ERROR = 11, 12, 13
EE = 14  # 3 entries: the end effector in the axle frame
CUP_POSE = 17  # 7 entries: position in the tray frame, quaternion (w >= 0)
CUP_TILT_DEG, CUP_UPRIGHT, CUP_ON_PLATE, TRAY_TILT_DEG = 24, 25, 26, 27
TRAY_OFFSET = 28  # 3 entries
TRAY_ON_HAND, CUP_FRICTION_USE = 31, 32
N_OUT = 33


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
    its site in the axle frame and its distance to ``floats[F_EE_REFERENCE:]``.

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
    base, wl, wr = ints[I_BASE], ints[I_WHEEL_L], ints[I_WHEEL_R]
    r = floats[F_WHEEL_RADIUS]
    ax, ay, az = xpos[base, 0], xpos[base, 1], xpos[base, 2]
    if ints[I_PLANAR]:
        c, s, psi, psid = 1.0, 0.0, 0.0, 0.0
        v = ints[I_ROOT_DOF]
        x = qpos[ints[I_ROOT_QPOS]]
        xd, voz, wy_ = qvel[v], qvel[v + 1], qvel[v + 2]
        vox, voy = xd, 0.0
        wx_ = wz_ = 0.0
    else:
        R = xmat[base]
        psi = math.atan2(-R[1], R[4])
        c, s = math.cos(psi), math.sin(psi)
        q1 = math.atan2(c * R[2] + s * R[5], R[8])
        v = ints[I_ROOT_DOF]
        vox, voy, voz = qvel[v], qvel[v + 1], qvel[v + 2]
        w0, w1, w2 = qvel[v + 3], qvel[v + 4], qvel[v + 5]
        wx_ = R[0] * w0 + R[1] * w1 + R[2] * w2
        wy_ = R[3] * w0 + R[4] * w1 + R[5] * w2
        wz_ = psid = R[6] * w0 + R[7] * w1 + R[8] * w2
        q1d = -s * wx_ + c * wy_
        x = r * 0.5 * (qpos[ints[I_QPOS_L]] + qpos[ints[I_QPOS_R]]) + r * q1
        xd = r * 0.5 * (qvel[ints[I_DOF_L]] + qvel[ints[I_DOF_R]]) + r * q1d
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
    out[X], out[XD], out[THETA] = x, xd, theta
    out[THETAD] = (Z_ * Xd - X_ * Zd) / distance_sq if distance_sq > 1e-18 else 0.0
    out[PSI], out[PSID], out[COS_PSI], out[SIN_PSI] = psi, psid, c, s
    out[AXLE], out[AXLE + 1], out[AXLE + 2] = ax, ay, az
    gx, gy = floats[F_GOAL_X], floats[F_GOAL_Y]
    if ints[I_PLANAR]:
        out[GOAL_DISTANCE] = abs(gx - ax)
    else:
        out[GOAL_DISTANCE] = math.hypot(gx - ax, gy - ay)

    # the fall: the pitch, or a body geom on the floor
    ncon = contact_geom.shape[0]
    fallen = abs(theta) > floats[F_FALL_ANGLE]
    if not fallen:
        floor = ints[I_FLOOR]
        for i in range(ncon):
            g1, g2 = contact_geom[i, 0], contact_geom[i, 1]
            if g1 < 0 or g2 < 0:  # a flex's contact, not a pair of geoms
                continue
            if (g1 == floor and ints[N_INTS + g2] & GEOM_FALL) or (
                g2 == floor and ints[N_INTS + g1] & GEOM_FALL
            ):
                fallen = True
                break
    out[FALLEN] = 1.0 if fallen else 0.0

    ee = ints[I_EE_SITE]
    if ee >= 0:
        ex, ey, ez = site_xpos[ee, 0] - ax, site_xpos[ee, 1] - ay, site_xpos[ee, 2] - az
        ex, ey = c * ex + s * ey, -s * ex + c * ey
        out[EE], out[EE + 1], out[EE + 2] = ex, ey, ez
        ex -= floats[F_EE_REFERENCE]
        ey -= floats[F_EE_REFERENCE + 1]
        ez -= floats[F_EE_REFERENCE + 2]
        out[EE_ERROR] = math.sqrt(ex * ex + ey * ey + ez * ez)
    if not ints[I_TRAY]:
        return

    # the cup's pose in the tray frame
    tray, cup = ints[I_TRAY_BODY], ints[I_CUP_BODY]
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
    out[CUP_POSE], out[CUP_POSE + 1], out[CUP_POSE + 2] = px, py, pz
    out[CUP_POSE + 3], out[CUP_POSE + 4], out[CUP_POSE + 5], out[CUP_POSE + 6] = w, qx, qy, qz

    # its state: R[2, 2] of the quaternion is the cosine of the tilt
    cos_tilt = min(1.0, max(-1.0, 1.0 - 2.0 * (qx * qx + qy * qy)))
    tilt = math.degrees(math.acos(cos_tilt))
    sin_tilt = math.sqrt(max(0.0, 1.0 - cos_tilt * cos_tilt))
    top = 2 * _HALF_Z
    lowest = pz - CUP_HALF_HEIGHT * abs(cos_tilt) - CUP_RADIUS * sin_tilt
    on_plate = (
        abs(px) <= _HALF_X and abs(py) <= _HALF_Y and pz > top and lowest - top <= CUP_PLATE_GAP
    )
    out[CUP_TILT_DEG] = tilt
    out[CUP_UPRIGHT] = 1.0 if tilt <= CUP_UPRIGHT_DEG else 0.0
    out[CUP_ON_PLATE] = 1.0 if on_plate else 0.0
    out[TRAY_TILT_DEG] = math.degrees(math.acos(min(1.0, max(-1.0, T[8]))))

    # the free tray's place on the hand
    if ints[I_FREE_TRAY]:
        rest = ints[I_REST_SITE]
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
    out[TRAY_OFFSET], out[TRAY_OFFSET + 1], out[TRAY_OFFSET + 2] = ox, oy, oz
    out[TRAY_ON_HAND] = 1.0 if on_hand else 0.0

    # the cup's friction use on the plate, from the contact-frame forces
    plate = ints[I_TRAY_GEOM]
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
    out[CUP_FRICTION_USE] = 0.0
    if normal > 0.0:
        out[CUP_FRICTION_USE] = math.sqrt(tx * tx + ty * ty + tz * tz) / (
            floats[F_CUP_FRICTION] * normal
        )


# the table of addresses of env_measures: the model, the data, the arrays step_measures reads
# (in its order), their lengths, and where the data's contacts are
T_MODEL, T_DATA = 0, 1
T_ARRAYS = 2  # 12 addresses: qpos, qvel, xpos ... site_xmat, body_subtreemass, body_mass
T_NQ, T_NV, T_NBODY, T_NSITE = 14, 15, 16, 17
T_CONTACT_GEOM, T_CONTACT_FRAME, T_CONTACT_STRIDE, T_CONTACT_CAPACITY = 18, 19, 20, 21
N_TABLE = 22


def address_table(model: Any, data: Any) -> np.ndarray:
    """The table of :func:`env_measures`: the addresses of ``model``, ``data`` and the arrays
    :func:`step_measures` reads (MuJoCo allocates them once per MjModel/MjData: the table is
    valid while both live), their sizes, and the contacts' layout (``mujoco_c.contact_layout``)."""
    arrays = (
        data.qpos,
        data.qvel,
        data.xpos,
        data.xmat,
        data.xquat,
        data.xipos,
        data.subtree_com,
        data.subtree_linvel,
        data.site_xpos,
        data.site_xmat,
        model.body_subtreemass,
        model.body_mass,
    )
    for i, array in enumerate(arrays):
        if array.dtype != np.float64 or not array.flags.c_contiguous:
            raise ValueError(f"array {i} of the env's table is not C-contiguous float64")
    table = np.zeros(N_TABLE, np.int64)
    table[T_MODEL], table[T_DATA] = mjc.addresses(model, data)
    table[T_ARRAYS : T_ARRAYS + len(arrays)] = [array.ctypes.data for array in arrays]
    table[T_NQ], table[T_NV], table[T_NBODY], table[T_NSITE] = (
        model.nq,
        model.nv,
        model.nbody,
        model.nsite,
    )
    table[T_CONTACT_GEOM : T_CONTACT_CAPACITY + 1] = contact_layout(data)
    return table


@njit(cache=True)
def gather_contacts(
    table: np.ndarray, ncon: int, forces: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first ``ncon`` contacts of the data of ``table`` (:func:`address_table`), read
    through ``mujoco_c.contact_layout``: their geom pairs, frames and, if ``forces``, the first
    three entries of ``mj_contactForce`` (normal, tangent 1, tangent 2 in the contact frame; zeros
    otherwise). Raises if ``ncon`` is more than the arena holds (it must be ``data.ncon``)."""
    if ncon < 0 or ncon > table[T_CONTACT_CAPACITY]:
        raise ValueError("ncon must be data.ncon: more contacts than the data's arena holds")
    model, data = np.uint64(table[T_MODEL]), np.uint64(table[T_DATA])
    geom = np.empty((ncon, 2), np.int32)
    frame = np.empty((ncon, 9))
    force = np.zeros((ncon, 3))
    result = np.empty(6)
    stride = table[T_CONTACT_STRIDE]
    for i in range(ncon):
        pair = carray(int32_pointer(np.uint64(table[T_CONTACT_GEOM] + i * stride)), 2)
        geom[i, 0], geom[i, 1] = pair[0], pair[1]
        frame[i] = float64_view(table[T_CONTACT_FRAME] + i * stride, (9,))
        if forces:
            mjc.mj_contactForce(model, data, i, result.ctypes.data)
            force[i, 0], force[i, 1], force[i, 2] = result[0], result[1], result[2]
    return geom, frame, force


@njit(cache=True, nogil=True)
def env_measures(
    table: np.ndarray, ncon: int, ints: np.ndarray, floats: np.ndarray, out: np.ndarray
) -> None:
    """MuJoCo's kinematics, ``mj_comPos``, ``mj_comVel`` and ``mj_subtreeVel`` on the data of
    ``table`` (:func:`address_table`), its first ``ncon`` (``data.ncon``) contacts
    (:func:`gather_contacts`; their forces only on a tray task, for the cup's friction use),
    then :func:`step_measures` on its arrays: the env's measures after a step in one compiled
    call."""
    model, data = np.uint64(table[T_MODEL]), np.uint64(table[T_DATA])
    mjc.mj_kinematics(model, data)
    mjc.mj_comPos(model, data)
    mjc.mj_comVel(model, data)  # mj_subtreeVel reads the bodies' velocities (cvel)
    mjc.mj_subtreeVel(model, data)
    geom, frame, force = gather_contacts(table, ncon, ints[I_TRAY] != 0)
    nbody, nsite = table[T_NBODY], table[T_NSITE]
    a = T_ARRAYS

    def view(i: int, shape: tuple[int, ...]) -> np.ndarray:
        return float64_view(table[a + i], shape)

    step_measures(
        view(0, (table[T_NQ],)),
        view(1, (table[T_NV],)),
        view(2, (nbody, 3)),
        view(3, (nbody, 9)),
        view(4, (nbody, 4)),
        view(5, (nbody, 3)),
        view(6, (nbody, 3)),
        view(7, (nbody, 3)),
        view(8, (nsite, 3)),
        view(9, (nsite, 9)),
        view(10, (nbody,)),
        view(11, (nbody,)),
        geom,
        frame,
        force,
        ints,
        floats,
        out,
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


#: the env's version: its table, ``data.ncon``, its parameters and results
ENV_SIGNATURE = types.void(types.int64[::1], types.intp, types.int64[::1], _F1, _F1)

#: an action of any layout, read-only too (``np.asarray`` of a JAX array)
ACTION_SIGNATURE = types.float64(types.Array(types.float64, 1, "A", readonly=True), _F2)


def compile_once() -> None:
    """Compile :func:`step_measures` for :data:`SIGNATURE` and :func:`action_effort` for
    :data:`ACTION_SIGNATURE` (or load them from numba's cache) and no other versions: a call
    with arrays of another layout converts to them instead of compiling again (once per
    process; the env calls it when made)."""
    for kernel, signature in (
        (step_measures, SIGNATURE),
        (env_measures, ENV_SIGNATURE),
        (action_effort, ACTION_SIGNATURE),
    ):
        if not kernel.signatures:
            kernel.compile(signature)
            kernel.disable_compile()
