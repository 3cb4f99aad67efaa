"""The env step's numbers, readable: plain Python floats through MuJoCo's Python bindings.

The definition of what ``WIPEnv.step`` measures after its physics, and the env's readable path
(``wip_gym.mujoco_c.fast_path``): :func:`measures` fills the same vector as the compiled
``wip_gym.envs.measures.env_measures`` (the fast path), from the same parameters, and
``tests/test_env_step_reference.py`` holds the two equal step by step on every env, in the tray
variants whose branches the defaults leave out (a free tray, a push, a payload appearing in the
hand, a cup that is lost). :func:`friction_use` is the cup's (and a free tray's) friction use
on its plate, read anywhere from a model and data.
"""

from __future__ import annotations

import math
from collections.abc import Collection

import mujoco
import numpy as np
from numpy.typing import NDArray

from wip_gym.envs.measures import (
    CUP_PLATE_GAP,
    CUP_UPRIGHT_DEG,
    FLOAT,
    GEOM_CUP,
    GEOM_FALL,
    INT,
    N_INTS,
    OUT,
    TRAY_HAND_GAP,
)
from wip_gym.scene import CUP_HALF_HEIGHT, CUP_RADIUS, TRAY_HALF_SIZE

Array = NDArray[np.float64]


def friction_use(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    geoms: Collection[int],
    plate: int,
    mu: float,
) -> float:
    """Friction use of a body on a plate: the norm of the net tangential force over ``mu`` times
    the net normal force, summed over the contacts between the geom ``plate`` and the geoms
    ``geoms`` (ids; 1: the body slides); 0 without contact.

    The forces are summed as vectors before the ratio: the ratio is how much of the friction
    the net push along the plate uses (a resting cup on a still plate tilted by alpha uses
    ``tan(alpha) / mu``). Contacts of other geoms (a rim) do not count: a rim's push on the
    cup is a normal force of the rim, not friction of the plate.
    """
    n = data.ncon
    if n == 0:
        return 0.0
    contact = data.contact
    pairs = contact.geom[:n].tolist()
    rows = [
        i
        for i, (g1, g2) in enumerate(pairs)
        if (g1 == plate and g2 in geoms) or (g2 == plate and g1 in geoms)
    ]
    if not rows:
        return 0.0
    frames = contact.frame[:n].tolist()
    wrench = np.zeros(6)
    normal = tx = ty = tz = 0.0
    for i in rows:
        # the contact-frame force (normal, tangent 1, tangent 2), either cone; zeros for a
        # contact excluded from the constraints
        mujoco.mj_contactForce(model, data, i, wrench)
        f_n, f_1, f_2 = wrench[:3].tolist()
        # rows of the contact frame: normal, tangent 1, tangent 2
        _, _, _, a0, a1, a2, b0, b1, b2 = frames[i]
        normal += f_n
        tx += f_1 * a0 + f_2 * b0
        ty += f_1 * a1 + f_2 * b1
        tz += f_1 * a2 + f_2 * b2
    if normal <= 0.0:
        return 0.0
    return math.sqrt(tx * tx + ty * ty + tz * tz) / (mu * normal)


def _robot(
    model: mujoco.MjModel, data: mujoco.MjData, ints: list[int], r: float
) -> tuple[float, ...]:
    """``(x, xd, theta, thetad, psi, psid, cos psi, sin psi)`` of the robot: the heading of the
    base's yaw, ``x = r (phi_L + phi_R) / 2 + r q1`` (planar: the root slide), and the body
    CoM's (the robot's subtree less the wheels, whose CoMs sit on the axle) pitch about the
    axle in the heading frame and its rate."""
    base, wl, wr = ints[INT.base], ints[INT.wheel_left], ints[INT.wheel_right]
    qpos, qvel = data.qpos, data.qvel
    v = ints[INT.root_dof]
    if ints[INT.planar]:
        c, s, psi, psid = 1.0, 0.0, 0.0, 0.0
        x, xd = float(qpos[ints[INT.root_qpos]]), float(qvel[v])
        vox, voy, voz = xd, 0.0, float(qvel[v + 1])
        wx, wy, wz = 0.0, float(qvel[v + 2]), 0.0
    else:
        R00, R01, R02, R10, R11, R12, R20, R21, R22 = data.xmat[base].tolist()
        psi = math.atan2(-R01, R11)
        c, s = math.cos(psi), math.sin(psi)
        q1 = math.atan2(c * R02 + s * R12, R22)
        vox, voy, voz, w0, w1, w2 = qvel[v : v + 6].tolist()
        wx = R00 * w0 + R01 * w1 + R02 * w2
        wy = R10 * w0 + R11 * w1 + R12 * w2
        wz = psid = R20 * w0 + R21 * w1 + R22 * w2
        q1d = -s * wx + c * wy
        x = r * 0.5 * (qpos[ints[INT.qpos_left]] + qpos[ints[INT.qpos_right]]) + r * q1
        xd = r * 0.5 * (qvel[ints[INT.dof_left]] + qvel[ints[INT.dof_right]]) + r * q1d
    mass = float(model.body_subtreemass[base])
    ml, mr = float(model.body_mass[wl]), float(model.body_mass[wr])
    body = mass - ml - mr
    ax, ay, az = data.xpos[base].tolist()
    cx, cy, cz = data.subtree_com[base].tolist()
    lx, ly, lz = data.xipos[wl].tolist()
    rx, ry, rz = data.xipos[wr].tolist()
    vx, vy, vz = data.subtree_linvel[base].tolist()
    dx = (mass * cx - ml * lx - mr * rx) / body - ax
    dy = (mass * cy - ml * ly - mr * ry) / body - ay
    dz = (mass * cz - ml * lz - mr * rz) / body - az
    # sum over the wheels of m_w (v_o + omega x (p_w - o)) = (ml + mr) v_o + omega x s_w
    sx = ml * (lx - ax) + mr * (rx - ax)
    sy = ml * (ly - ay) + mr * (ry - ay)
    sz = ml * (lz - az) + mr * (rz - az)
    wheels = ml + mr
    dvx = (mass * vx - wheels * vox - (wy * sz - wz * sy)) / body - vox
    dvy = (mass * vy - wheels * voy - (wz * sx - wx * sz)) / body - voy
    dvz = (mass * vz - wheels * voz - (wx * sy - wy * sx)) / body - voz
    X, Y, Z = c * dx + s * dy, -s * dx + c * dy, dz
    Xd, Zd = c * dvx + s * dvy + psid * Y, dvz
    distance_sq = X * X + Z * Z
    theta = math.atan2(X, Z)
    thetad = (Z * Xd - X * Zd) / distance_sq if distance_sq > 1e-18 else 0.0
    return float(x), float(xd), theta, thetad, psi, psid, c, s


def _fallen(data: mujoco.MjData, ints: list[int], theta: float, fall_angle: float) -> bool:
    """``|theta|`` beyond the fall angle, or a robot body geom touching the floor."""
    if abs(theta) > fall_angle:
        return True
    floor, bits = ints[INT.floor], ints[N_INTS:]
    return any(
        (g1 == floor and bits[g2] & GEOM_FALL) or (g2 == floor and bits[g1] & GEOM_FALL)
        for g1, g2 in data.contact.geom[: data.ncon].tolist()
        if g1 >= 0 and g2 >= 0  # a flex's contact is no pair of geoms
    )


def _cup_in_tray_frame(data: mujoco.MjData, tray: int, cup: int) -> tuple[Array, Array]:
    """The cup's position in the tray frame and its quaternion relative to the tray's
    (``w >= 0``)."""
    position = data.xmat[tray].reshape(3, 3).T @ (data.xpos[cup] - data.xpos[tray])
    inverse, relative = np.zeros(4), np.zeros(4)
    mujoco.mju_negQuat(inverse, data.xquat[tray])
    mujoco.mju_mulQuat(relative, inverse, data.xquat[cup])
    if relative[0] < 0.0:
        relative = -relative
    return position, relative


def _cup_state(position: Array, quat: Array) -> tuple[float, bool, bool]:
    """The cup's tilt from the tray's normal (deg), whether it is upright, and whether it is
    on the plate (its centre over it and above it, its lowest point at most ``CUP_PLATE_GAP``
    above its top)."""
    _, x, y, _ = quat.tolist()
    cos_tilt = min(1.0, max(-1.0, 1.0 - 2.0 * (x * x + y * y)))
    tilt = math.degrees(math.acos(cos_tilt))
    sin_tilt = math.sqrt(max(0.0, 1.0 - cos_tilt * cos_tilt))
    top = 2 * TRAY_HALF_SIZE[2]
    px, py, pz = position.tolist()
    lowest = pz - CUP_HALF_HEIGHT * abs(cos_tilt) - CUP_RADIUS * sin_tilt
    on_plate = (
        abs(px) <= TRAY_HALF_SIZE[0]
        and abs(py) <= TRAY_HALF_SIZE[1]
        and pz > top
        and lowest - top <= CUP_PLATE_GAP
    )
    return tilt, tilt <= CUP_UPRIGHT_DEG, on_plate


def _tray_on_hand(data: mujoco.MjData, ints: list[int]) -> tuple[Array, bool]:
    """A free tray's offset from its rest place (the ``tray_rest`` site's frame) and whether it
    is on the hand; zeros and True for a welded one."""
    if not ints[INT.free_tray]:
        return np.zeros(3), True
    rest, tray = ints[INT.rest_site], ints[INT.tray_body]
    offset = data.site_xmat[rest].reshape(3, 3).T @ (data.xpos[tray] - data.site_xpos[rest])
    ox, oy, oz = offset.tolist()
    on_hand = (
        abs(oz) <= TRAY_HAND_GAP and abs(ox) <= TRAY_HALF_SIZE[0] and abs(oy) <= TRAY_HALF_SIZE[1]
    )
    return offset, on_hand


def measures(
    model: mujoco.MjModel, data: mujoco.MjData, ints: NDArray[np.int64], floats: Array, out: Array
) -> None:
    """Every number of the step's observation, reward and info into ``out`` (the layout
    ``OUT`` of ``wip_gym.envs.measures``; flags as 0.0 / 1.0), from MuJoCo's kinematics,
    ``mj_comPos``, ``mj_comVel`` and ``mj_subtreeVel`` on ``data`` and its contacts; ``ints``
    and ``floats`` the parameters (``INT`` and the geoms' bits, ``FLOAT``)."""
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    mujoco.mj_comVel(model, data)
    mujoco.mj_subtreeVel(model, data)
    p, f = ints.tolist(), floats.tolist()
    x, xd, theta, thetad, psi, psid, c, s = _robot(model, data, p, f[FLOAT.wheel_radius])
    axle = data.xpos[p[INT.base]]
    ax, ay, az = axle.tolist()
    gx, gy = f[FLOAT.goal], f[FLOAT.goal + 1]
    out[OUT.x], out[OUT.xd], out[OUT.theta], out[OUT.thetad] = x, xd, theta, thetad
    out[OUT.psi], out[OUT.psid], out[OUT.cos_psi], out[OUT.sin_psi] = psi, psid, c, s
    out[OUT.axle : OUT.axle + 3] = axle
    out[OUT.goal_distance] = abs(gx - ax) if p[INT.planar] else math.hypot(gx - ax, gy - ay)
    out[OUT.fallen] = float(_fallen(data, p, theta, f[FLOAT.fall_angle]))
    if p[INT.ee_site] >= 0:
        dx, dy, dz = (data.site_xpos[p[INT.ee_site]] - axle).tolist()
        ee = [c * dx + s * dy, -s * dx + c * dy, dz]
        out[OUT.ee : OUT.ee + 3] = ee
        ex, ey, ez = (e - r for e, r in zip(ee, f[FLOAT.ee_reference :], strict=False))
        out[OUT.ee_error] = math.sqrt(ex * ex + ey * ey + ez * ez)
    if not p[INT.tray]:
        return
    tray = p[INT.tray_body]
    position, quat = _cup_in_tray_frame(data, tray, p[INT.cup_body])
    tilt, upright, on_plate = _cup_state(position, quat)
    out[OUT.cup_pose : OUT.cup_pose + 3] = position
    out[OUT.cup_pose + 3 : OUT.cup_pose + 7] = quat
    out[OUT.cup_tilt_deg] = tilt
    out[OUT.cup_upright], out[OUT.cup_on_plate] = float(upright), float(on_plate)
    normal_z = float(data.xmat[tray, 8])  # the tray's normal's world z
    out[OUT.tray_tilt_deg] = math.degrees(math.acos(min(1.0, max(-1.0, normal_z))))
    offset, on_hand = _tray_on_hand(data, p)
    out[OUT.tray_offset : OUT.tray_offset + 3] = offset
    out[OUT.tray_on_hand] = float(on_hand)
    cup_geoms = [g for g, bits in enumerate(p[N_INTS:]) if bits & GEOM_CUP]
    out[OUT.cup_friction_use] = friction_use(
        model, data, cup_geoms, p[INT.tray_geom], f[FLOAT.cup_friction]
    )


def action_effort(action: Array, table: Array) -> float:
    """``sum((action / scale)^2)`` (the ctrl cost's effort) if every torque is within its band
    ``table[0] <= action <= table[1]`` (``scale = table[2]``), else NaN (also for a NaN
    torque)."""
    low, high, scale = table
    if not ((action >= low) & (action <= high)).all():
        return math.nan
    scaled = action / scale
    return float(scaled @ scaled)
