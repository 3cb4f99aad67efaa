"""The env's step as it was computed before it was made lean (wip_gym/envs/base.py at 61c923a):
the record of what ``WIPEnv.step`` computes, for tests/test_env_step_reference.py to compare the
env's step with, on the same states.

Every function takes the env (a ``WIPEnv``) and reads its model, data and settings; only
``reference_step`` changes the env (its data and its episode state, as ``step`` does).
"""

from __future__ import annotations

import math
from collections.abc import Collection
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from wip_gym.envs.base import CUP_PLATE_GAP, CUP_UPRIGHT_DEG, TRAY_HAND_GAP, WIPEnv
from wip_gym.scene import CUP_HALF_HEIGHT, CUP_RADIUS, TRAY_HALF_SIZE

CupFrame = tuple[NDArray[np.float64], NDArray[np.float64]]


def friction_use(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    geoms: Collection[int],
    plate: int,
    mu: float,
) -> float:
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
        mujoco.mj_contactForce(model, data, i, wrench)  # zeros for an excluded contact
        f_n, f_1, f_2 = wrench[:3].tolist()
        _, _, _, a0, a1, a2, b0, b1, b2 = frames[i]
        normal += f_n
        tx += f_1 * a0 + f_2 * b0
        ty += f_1 * a1 + f_2 * b1
        tz += f_1 * a2 + f_2 * b2
    if normal <= 0.0:
        return 0.0
    return math.sqrt(tx * tx + ty * ty + tz * tz) / (mu * normal)


def check_action(env: WIPEnv, action: Any) -> NDArray[np.float64]:
    a = np.asarray(action, dtype=np.float64)
    if a.shape != env.action_space.shape:
        raise ValueError("shape")
    low, high = env._action_band
    if ((a >= low) & (a <= high)).all():
        return a
    raise ValueError("action")


def measure(env: WIPEnv) -> None:
    """The old ``_measure``: sets ``env._theta`` ... ``env._axle`` as it did."""
    m, d, lay = env.model, env.data, env._layout
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    mujoco.mj_comVel(m, d)
    mujoco.mj_subtreeVel(m, d)
    base = lay.base_body
    qpos, qvel = d.qpos, d.qvel
    r = lay.wheel_radius
    wl, wr = lay.wheel_bodies
    axle = d.xpos[base]
    if lay.planar:
        o, v = lay.root_qpos, lay.root_dof
        c, s, psi, psid = 1.0, 0.0, 0.0, 0.0
        x, xd = float(qpos[o]), float(qvel[v])
        vox, voy, voz = xd, 0.0, float(qvel[v + 1])
    else:
        R00, R01, R02, R10, R11, R12, R20, R21, R22 = d.xmat[base].tolist()
        psi = math.atan2(-R01, R11)
        c, s = math.cos(psi), math.sin(psi)
        q1 = math.atan2(c * R02 + s * R12, R22)
        v = lay.root_dof
        vox, voy, voz, w0, w1, w2 = qvel[v : v + 6].tolist()
        omega_x = R00 * w0 + R01 * w1 + R02 * w2
        omega_y = R10 * w0 + R11 * w1 + R12 * w2
        psid = R20 * w0 + R21 * w1 + R22 * w2
        q1d = -s * omega_x + c * omega_y
        ql, qr = lay.wheel_qpos
        dl, dr = lay.wheel_dof
        x = r * 0.5 * (qpos[ql] + qpos[qr]) + r * q1
        xd = r * 0.5 * (qvel[dl] + qvel[dr]) + r * q1d
    mass = float(m.body_subtreemass[base])
    ml, mr = float(m.body_mass[wl]), float(m.body_mass[wr])
    body = mass - ml - mr
    ax, ay, az = axle.tolist()
    cx, cy, cz = d.subtree_com[base].tolist()
    lx, ly, lz = d.xipos[wl].tolist()
    rx, ry, rz = d.xipos[wr].tolist()
    vx, vy, vz = d.subtree_linvel[base].tolist()
    dx = (mass * cx - ml * lx - mr * rx) / body - ax
    dy = (mass * cy - ml * ly - mr * ry) / body - ay
    dz = (mass * cz - ml * lz - mr * rz) / body - az
    sx = ml * (lx - ax) + mr * (rx - ax)
    sy = ml * (ly - ay) + mr * (ry - ay)
    sz = ml * (lz - az) + mr * (rz - az)
    if lay.planar:
        wx_, wy_, wz_ = 0.0, float(qvel[lay.root_dof + 2]), 0.0
    else:
        wx_, wy_, wz_ = omega_x, omega_y, psid
    wheels = ml + mr
    dvx = (mass * vx - wheels * vox - (wy_ * sz - wz_ * sy)) / body - vox
    dvy = (mass * vy - wheels * voy - (wz_ * sx - wx_ * sz)) / body - voy
    dvz = (mass * vz - wheels * voz - (wx_ * sy - wy_ * sx)) / body - voz
    X, Y, Z = c * dx + s * dy, -s * dx + c * dy, dz
    Xd = c * dvx + s * dvy + psid * Y
    Zd = dvz
    distance_sq = X * X + Z * Z
    env._theta = math.atan2(X, Z)
    env._thetad = (Z * Xd - X * Zd) / distance_sq if distance_sq > 1e-18 else 0.0
    env._x, env._xd, env._psi, env._psid = float(x), float(xd), psi, psid
    env._cos_psi, env._sin_psi = c, s
    env._axle = axle.copy()


def goal_distance(env: WIPEnv) -> float:
    axle = env._axle
    if env._spec.planar:
        return abs(float(env._goal[0]) - float(axle[0]))
    return math.hypot(float(env._goal[0] - axle[0]), float(env._goal[1] - axle[1]))


def ee_in_axle_frame(env: WIPEnv) -> NDArray[np.float64]:
    if env._ee_site < 0:
        return np.zeros(3)
    dx, dy, dz = (env.data.site_xpos[env._ee_site] - env._axle).tolist()
    c, s = env._cos_psi, env._sin_psi
    return np.array([c * dx + s * dy, -s * dx + c * dy, dz])


def fallen(env: WIPEnv) -> bool:
    if abs(env._theta) > env._fall_angle:
        return True
    d = env.data
    if d.ncon == 0:
        return False
    floor, body = env._floor, env._body_geom_set
    return any(
        (g1 == floor and g2 in body) or (g2 == floor and g1 in body)
        for g1, g2 in d.contact.geom[: d.ncon].tolist()
    )


def cup_in_tray_frame(env: WIPEnv) -> CupFrame:
    d = env.data
    tray, cup = env._tray_body, env._cup_body
    position = d.xmat[tray].reshape(3, 3).T @ (d.xpos[cup] - d.xpos[tray])
    inverse, rel = np.zeros(4), np.zeros(4)
    mujoco.mju_negQuat(inverse, d.xquat[tray])
    mujoco.mju_mulQuat(rel, inverse, d.xquat[cup])
    if rel[0] < 0.0:
        rel = -rel
    return position, rel


def cup_state(cup_frame: CupFrame) -> tuple[float, bool, bool]:
    p, q = cup_frame
    w, x, y, _ = q.tolist()
    cos_tilt = min(1.0, max(-1.0, 1.0 - 2.0 * (x * x + y * y)))
    tilt = math.degrees(math.acos(cos_tilt))
    sin_tilt = math.sqrt(max(0.0, 1.0 - cos_tilt * cos_tilt))
    top = 2 * TRAY_HALF_SIZE[2]
    px, py, pz = p.tolist()
    lowest = pz - CUP_HALF_HEIGHT * abs(cos_tilt) - CUP_RADIUS * sin_tilt
    on_plate = (
        abs(px) <= TRAY_HALF_SIZE[0]
        and abs(py) <= TRAY_HALF_SIZE[1]
        and pz > top
        and lowest - top <= CUP_PLATE_GAP
    )
    return tilt, tilt <= CUP_UPRIGHT_DEG, on_plate


def tray_on_hand(env: WIPEnv) -> tuple[NDArray[np.float64], bool]:
    if not env._free_tray:
        return np.zeros(3), True
    d = env.data
    rest = env._tray_rest_site
    offset = d.site_xmat[rest].reshape(3, 3).T @ (d.xpos[env._tray_body] - d.site_xpos[rest])
    ox, oy, oz = offset.tolist()
    on_hand = (
        abs(oz) <= TRAY_HAND_GAP and abs(ox) <= TRAY_HALF_SIZE[0] and abs(oy) <= TRAY_HALF_SIZE[1]
    )
    return offset, on_hand


def tray_tilt_deg(env: WIPEnv) -> float:
    z = float(env.data.xmat[env._tray_body, 8])
    return math.degrees(math.acos(min(1.0, max(-1.0, z))))


def info_of(env: WIPEnv, *, is_fallen: bool, distance: float | None = None) -> dict[str, Any]:
    info: dict[str, Any] = {
        "x": env._x,
        "xd": env._xd,
        "theta": env._theta,
        "thetad": env._thetad,
        "axle_position": env._axle,
        "goal_distance": goal_distance(env) if distance is None else distance,
        "fallen": bool(is_fallen),
    }
    if not env._spec.planar:
        info["psi"] = env._psi
        info["psid"] = env._psid
    if env._ee_site >= 0:
        ex, ey, ez = (ee_in_axle_frame(env) - env._ee_reference).tolist()
        info["ee_error"] = math.sqrt(ex * ex + ey * ey + ez * ez)
    return info


def tray_info(
    env: WIPEnv,
    info: dict[str, Any],
    cup_frame: CupFrame,
    state: tuple[float, bool, bool],
    tray_state: tuple[NDArray[np.float64], bool],
) -> None:
    tilt, upright, on_plate = state
    tray_offset, on_hand = tray_state
    info["tray_tilt_deg"] = tray_tilt_deg(env)
    info["cup_offset"] = cup_frame[0]
    info["cup_tilt_deg"] = tilt
    info["cup_upright"] = upright
    info["cup_on_plate"] = on_plate
    info["cup_on_tray"] = on_plate and upright
    info["cup_friction_use"] = friction_use(
        env.model, env.data, env._cup_geoms, env._tray_geom, env._cup_friction
    )
    info["tray_offset"] = tray_offset
    info["tray_on_hand"] = on_hand


def get_obs(env: WIPEnv, cup_frame: CupFrame | None = None) -> dict[str, NDArray[np.float64]]:
    d = env.data
    obs = {
        "qpos": d.qpos[: env._nq].copy(),
        "qvel": d.qvel[: env._nv].copy(),
        "goal": env._goal.copy(),
    }
    if env._tray:
        position, quat = cup_frame or cup_in_tray_frame(env)
        obs["cup_pose"] = np.concatenate([position, quat])
    return obs


def reference_step(
    env: WIPEnv, action: Any
) -> tuple[dict[str, NDArray[np.float64]], float, bool, bool, dict[str, Any]]:
    """The old ``WIPEnv.step`` (without rendering)."""
    action = check_action(env, action)
    m, d = env.model, env.data
    t = d.time
    force, start, duration = env._push
    d.xfrc_applied[env._push_body, :] = 0.0
    if force != 0.0 and start <= t < start + duration:
        d.xfrc_applied[env._push_body, :3] = (force * env._cos_psi, force * env._sin_psi, 0)
    if not env._payload_attached and t >= env._payload_time:
        m.body_mass[env._payload_body] = env._payload_mass
        m.body_inertia[env._payload_body] = env._nominal_inertia[env._payload_body]
        mujoco.mj_setConst(m, mujoco.MjData(m))
        env._payload_attached = True
    d.ctrl[:] = action
    mujoco.mj_step(m, d, nstep=env.frame_skip)
    measure(env)
    cup_frame = cup_in_tray_frame(env) if env._tray else None
    is_fallen = fallen(env)
    kept = True
    if cup_frame is not None:
        state = cup_state(cup_frame)
        tray_state = tray_on_hand(env)
        kept = state[1] and state[2] and tray_state[1]
    newly_lost = env._tray and not kept and not env._cup_lost
    env._cup_lost = env._cup_lost or not kept
    island = int(mujoco.mjtDisableBit.mjDSBL_ISLAND)
    if newly_lost and m.opt.disableflags & island:
        # added since 61c923a: islands on from a cup's loss to the next reset (the models are
        # built with them off; WIPEnv._solve_by_islands)
        m.opt.disableflags &= ~island
        env._islands_switched_on = True
    distance = goal_distance(env)
    progress_w, ctrl_w, fall_pen, cup_pen = env._weights
    scaled = action / env._action_scale
    rewards = {
        "reward_progress": progress_w * (env._prev_distance - distance),
        "reward_ctrl": -ctrl_w * float(scaled @ scaled) * env.dt,
        "reward_fall": -fall_pen if is_fallen else 0.0,
        "reward_cup_loss": -cup_pen if newly_lost else 0.0,
    }
    env._prev_distance = distance
    reward = float(sum(rewards.values()))
    terminated = bool(is_fallen or (env._tray and env._terminate_on_cup_loss and env._cup_lost))
    info = info_of(env, is_fallen=is_fallen, distance=distance)
    if cup_frame is not None:
        tray_info(env, info, cup_frame, state, tray_state)
    info.update(rewards)
    return get_obs(env, cup_frame), reward, terminated, False, info


def reference_reset_info(env: WIPEnv) -> dict[str, Any]:
    """The old ``_get_reset_info`` (after ``reset_model``; the old ``_measure`` redone here at the
    reset state, which also gives a push in ``reference_step`` its first heading)."""
    measure(env)
    info = info_of(env, is_fallen=False)
    if env._tray:
        frame = cup_in_tray_frame(env)
        tray_info(env, info, frame, cup_state(frame), tray_on_hand(env))
    return info
