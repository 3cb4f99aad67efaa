"""Wrappers for learning on the wip-gym envs (docs/learning.md §5 and §6).

    env = wrap_for_learning(gym.make("wip_gym/WIP-v0", frame_skip=10), dense_reward=True,
                            goal_low=(-3, -3), goal_high=(3, 3))

* :class:`NormalizedObservation` (built on :class:`ObservationNormalizer`, a pure function of
  the env's ``Dict`` observation that a controller can call too): a flat ``Box`` of the goal in
  the robot's heading frame, gravity in the base frame, velocities scaled by documented
  constants, body joints scaled to their ranges, wheel angles dropped (or as sine and cosine),
  the cup's place and axis on the tray.
* :class:`ScaledAction`: actions in ``[-1, 1]`` mapped affinely onto the torque limits; beyond
  +-1 clipped and counted in ``info`` (``out_of_range="clip"``, the default) or a
  ``ValueError`` (``"error"``).
* :class:`DenseReward`: a reward on the benchmark's own measures (goal distance and progress,
  balance, control effort, tray tilt, cup friction use), each term in ``info["dense_*"]``.
* :class:`RandomGoal`: a goal drawn uniformly in a box at every reset (the env's
  ``reset(options={"goal": ...})``), reproducible from the reset's seed.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray

from wip_gym.envs.base import WIPEnv, wip_env
from wip_gym.robot_model import RobotLayout
from wip_gym.scene import CUP_HALF_HEIGHT, TRAY_HALF_SIZE

# ------------------------------------------------------------------------ observation scales
#: m: the goal's offset is given in units of the default goal's distance (2 m, every task)
GOAL_SCALE_M = 2.0
#: m/s: the model-based controllers' peak forward speed on the default 2 m drive is 1.1 to
#: 1.5 m/s (unified 1.21 and decoupled 1.41 on WIP-v0, 1.13 and 1.55 on Planar-v0; measured
#: with benchmarks.rollout, seed 0, docs/learning.md §5)
LINEAR_SPEED_SCALE = 1.5
#: rad/s: base angular rates and body joint rates; the same controllers' peak pitch rates are
#: 0.25 to 0.5 rad/s and their joints' below 0.35 rad/s; a fall reaches a few rad/s
ANGULAR_SPEED_SCALE = 1.0
#: the wheel speed scale is LINEAR_SPEED_SCALE over the wheel radius (rolling at that speed:
#: 6 rad/s for the 0.25 m wheels; the controllers peak at 4.9 to 6.7 rad/s)
WheelAngles = Literal["drop", "sincos"]
#: the cup's reset place in the tray frame (origin on the plate's underside): centred on the
#: plate, its centre a half height above the plate's top
CUP_REST_Z = 2 * TRAY_HALF_SIZE[2] + CUP_HALF_HEIGHT


@dataclass(frozen=True)
class ObservationNormalizer:
    """The flat, scaled observation of a wip-gym env, from its ``Dict`` observation alone.

    Components, in order (``names`` lists them):

    | block | size | value |
    |---|---|---|
    | goal | 2 (planar 1) | goal minus axle, in the heading frame (forward, left), / ``GOAL_SCALE_M`` |
    | gravity | 3 (planar 2: x, z) | the unit vector of gravity in the base frame (bounded by 1) |
    | base velocity | 3 (planar 2: x, z) | the axle's velocity in the heading frame / ``LINEAR_SPEED_SCALE`` |
    | base rate | 3 (planar 1: pitch) | the base's angular velocity in its own frame / ``ANGULAR_SPEED_SCALE`` |
    | wheel speeds | 2 | / (``LINEAR_SPEED_SCALE`` / wheel radius) |
    | wheel angles | 0 or 4 | ``"drop"``, or ``"sincos"``: sin, cos of the left, then the right |
    | joints | n | body joint angles: ``2 (q - low) / (high - low) - 1``, -1 to 1 over the joint's range (MuJoCo's limits are soft: a little beyond when pressed); a joint without a range: ``q`` in rad |
    | joint rates | n | / ``ANGULAR_SPEED_SCALE`` |
    | cup place | 3 (tray tasks) | cup centre in the tray frame minus its reset place, / (tray half-length, half-width, cup half-height) |
    | cup axis | 3 (tray tasks) | the cup's axis in the tray frame (bounded by 1) |

    The heading ``psi`` is the base's yaw (``atan2(-R01, R11)``, as the env's ``info["psi"]``);
    the axle is the base's origin (assets/mjcf/README.md). Nothing is clipped.
    """

    layout: RobotLayout
    tray: bool
    joint_low: tuple[float, ...]
    joint_high: tuple[float, ...]
    wheel_angles: WheelAngles = "drop"
    dtype: Any = np.float32

    @classmethod
    def for_env(
        cls, env: gym.Env[Any, Any], wheel_angles: WheelAngles = "drop", dtype: Any = np.float32
    ) -> ObservationNormalizer:
        """The normaliser of ``env``'s robot and task (a wip-gym env under any wrappers)."""
        base = wip_env(env)
        layout = base.robot.layout
        m = base.model
        low, high = [], []
        for address in layout.body_qpos:
            joint = int(np.flatnonzero(m.jnt_qposadr == address)[0])
            if m.jnt_limited[joint]:
                low.append(float(m.jnt_range[joint, 0]))
                high.append(float(m.jnt_range[joint, 1]))
            else:
                low.append(math.nan)
                high.append(math.nan)
        return cls(
            layout, bool(base.scene_options.tray), tuple(low), tuple(high), wheel_angles, dtype
        )

    def __post_init__(self) -> None:
        if self.wheel_angles not in ("drop", "sincos"):
            raise ValueError(f"wheel_angles must be 'drop' or 'sincos', got {self.wheel_angles!r}")
        if np.dtype(self.dtype) not in (np.dtype(np.float32), np.dtype(np.float64)):
            raise ValueError(f"dtype must be float32 or float64, got {self.dtype!r}")
        if len(self.joint_low) != len(self.layout.body_qpos) or len(self.joint_high) != len(
            self.joint_low
        ):
            raise ValueError("one joint range per body joint")

    @property
    def wheel_speed_scale(self) -> float:
        """rad/s: ``LINEAR_SPEED_SCALE`` over the wheel radius."""
        return LINEAR_SPEED_SCALE / self.layout.wheel_radius

    @property
    def names(self) -> list[str]:
        """One name per component, in order."""
        planar = self.layout.planar
        names = ["goal_forward"] if planar else ["goal_forward", "goal_left"]
        names += ["gravity_x", "gravity_z"] if planar else ["gravity_x", "gravity_y", "gravity_z"]
        names += (
            ["velocity_x", "velocity_z"] if planar else ["velocity_x", "velocity_y", "velocity_z"]
        )
        names += ["rate_pitch"] if planar else ["rate_x", "rate_y", "rate_z"]
        names += ["wheel_speed_left", "wheel_speed_right"]
        if self.wheel_angles == "sincos":
            names += ["sin_wheel_left", "cos_wheel_left", "sin_wheel_right", "cos_wheel_right"]
        joints = range(len(self.layout.body_qpos))
        names += [f"joint_{i}" for i in joints] + [f"joint_rate_{i}" for i in joints]
        if self.tray:
            names += ["cup_x", "cup_y", "cup_z", "cup_axis_x", "cup_axis_y", "cup_axis_z"]
        return names

    @property
    def size(self) -> int:
        return len(self.names)

    @property
    def bounded(self) -> NDArray[np.bool_]:
        """Which components are bounded by 1 in magnitude by construction (unit vectors, sine
        and cosine)."""
        return np.array(
            [n.startswith(("gravity_", "cup_axis_", "sin_", "cos_")) for n in self.names]
        )

    def space(self) -> spaces.Box:
        """The ``Box`` of the output: [-1, 1] on the bounded components, unbounded elsewhere."""
        bounded = self.bounded
        high = np.where(bounded, 1.0, np.inf).astype(self.dtype)
        return spaces.Box(-high, high, (self.size,), np.dtype(self.dtype))

    def __call__(self, observation: dict[str, NDArray[np.float64]]) -> NDArray[Any]:
        """The flat observation of one ``Dict`` observation."""
        lay = self.layout
        qpos, qvel, goal = observation["qpos"], observation["qvel"], observation["goal"]
        if np.shape(qpos) != (lay.nq,) or np.shape(qvel) != (lay.nv,) or np.shape(goal) != (2,):
            raise ValueError(
                f"observation shapes qpos {np.shape(qpos)}, qvel {np.shape(qvel)}, goal "
                f"{np.shape(goal)}; expected ({lay.nq},), ({lay.nv},), (2,)"
            )
        p = np.asarray(qpos, dtype=np.float64).tolist()
        u = np.asarray(qvel, dtype=np.float64).tolist()
        gx, gy = (float(g) for g in goal)
        r, v = lay.root_qpos, lay.root_dof
        lin, ang = 1.0 / LINEAR_SPEED_SCALE, 1.0 / ANGULAR_SPEED_SCALE
        if lay.planar:
            # slide x, slide z, pitch hinge about y: R = R_y(pitch), R^T (0, 0, -1) = (s, 0, -c)
            pitch = p[r + 2]
            out = [
                (gx - p[r]) / GOAL_SCALE_M,
                math.sin(pitch),
                -math.cos(pitch),
                u[v] * lin,
                u[v + 1] * lin,
                u[v + 2] * ang,
            ]
        else:
            R = _rotation(p[r + 3 : r + 7])
            psi = math.atan2(-R[1], R[4])
            c, s = math.cos(psi), math.sin(psi)
            dx, dy = gx - p[r], gy - p[r + 1]
            vx, vy, vz = u[v], u[v + 1], u[v + 2]  # free joint: world frame
            out = [
                (c * dx + s * dy) / GOAL_SCALE_M,
                (-s * dx + c * dy) / GOAL_SCALE_M,
                -R[6],  # R^T (0, 0, -1): minus the third row
                -R[7],
                -R[8],
                (c * vx + s * vy) * lin,
                (-s * vx + c * vy) * lin,
                vz * lin,
                u[v + 3] * ang,  # free joint: body frame
                u[v + 4] * ang,
                u[v + 5] * ang,
            ]
        wheel = 1.0 / self.wheel_speed_scale
        (ql, qr), (dl, dr) = lay.wheel_qpos, lay.wheel_dof
        out += [u[dl] * wheel, u[dr] * wheel]
        if self.wheel_angles == "sincos":
            out += [math.sin(p[ql]), math.cos(p[ql]), math.sin(p[qr]), math.cos(p[qr])]
        for address, low, high in zip(lay.body_qpos, self.joint_low, self.joint_high, strict=True):
            q = p[address]
            out.append(q if math.isnan(low) else 2.0 * (q - low) / (high - low) - 1.0)
        out += [u[d] * ang for d in lay.body_dof]
        if self.tray:
            cup = observation["cup_pose"]
            if np.shape(cup) != (7,):
                raise ValueError(f"cup_pose must have shape (7,), got {np.shape(cup)}")
            c7 = np.asarray(cup, dtype=np.float64).tolist()
            Rc = _rotation(c7[3:7])
            out += [
                c7[0] / TRAY_HALF_SIZE[0],
                c7[1] / TRAY_HALF_SIZE[1],
                (c7[2] - CUP_REST_Z) / CUP_HALF_HEIGHT,
                Rc[2],  # the cup's z axis in the tray frame: the third column
                Rc[5],
                Rc[8],
            ]
        return np.array(out, dtype=self.dtype)


def _rotation(quaternion: Sequence[float]) -> list[float]:
    """The rotation matrix (row-major, 9 floats) of a quaternion ``(w, x, y, z)``, normalised
    first; ``ValueError`` for a zero or non-finite one."""
    w, x, y, z = quaternion
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    if not (norm > 0.0 and math.isfinite(norm)):
        raise ValueError(f"not a rotation quaternion: {list(quaternion)}")
    w, x, y, z = w / norm, x / norm, y / norm, z / norm
    return [
        1 - 2 * (y * y + z * z),
        2 * (x * y - w * z),
        2 * (x * z + w * y),
        2 * (x * y + w * z),
        1 - 2 * (x * x + z * z),
        2 * (y * z - w * x),
        2 * (x * z - w * y),
        2 * (y * z + w * x),
        1 - 2 * (x * x + y * y),
    ]


class NormalizedObservation(
    gym.ObservationWrapper[NDArray[Any], Any, Any], gym.utils.RecordConstructorArgs
):
    """The env's ``Dict`` observation as :class:`ObservationNormalizer`'s flat ``Box``."""

    def __init__(
        self, env: gym.Env[Any, Any], wheel_angles: WheelAngles = "drop", dtype: Any = np.float32
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, wheel_angles=wheel_angles, dtype=dtype)
        gym.ObservationWrapper.__init__(self, env)
        self.normalizer = ObservationNormalizer.for_env(env, wheel_angles, dtype)
        self.observation_space = self.normalizer.space()

    def observation(self, observation: dict[str, NDArray[np.float64]]) -> NDArray[Any]:
        return self.normalizer(observation)


# ------------------------------------------------------------------------------ actions
OutOfRange = Literal["clip", "error"]


class ScaledAction(gym.ActionWrapper[Any, Any, Any], gym.utils.RecordConstructorArgs):
    """Actions in ``[-1, 1]`` per actuator: ``torque = mid + half * a`` with ``mid``, ``half``
    the centre and half-width of the actuator's torque limits (symmetric limits: ``a * limit``).

    ``out_of_range="clip"`` (the default: a Gaussian policy samples beyond +-1): an action
    beyond +-1 is clipped to it and counted: ``info["action_clipped"]`` (this step) and
    ``info["action_clip_steps"]`` (this episode; both also in the reset info, False and 0).
    ``"error"``: such an action raises ``ValueError``. A NaN or a wrong shape always raises.
    """

    def __init__(self, env: gym.Env[Any, Any], out_of_range: OutOfRange = "clip") -> None:
        if out_of_range not in ("clip", "error"):
            raise ValueError(f"out_of_range must be 'clip' or 'error', got {out_of_range!r}")
        gym.utils.RecordConstructorArgs.__init__(self, out_of_range=out_of_range)
        gym.ActionWrapper.__init__(self, env)
        base = wip_env(env)
        low = np.asarray(base.action_space.low, dtype=np.float64)
        high = np.asarray(base.action_space.high, dtype=np.float64)
        self.mid, self.half = (high + low) / 2.0, (high - low) / 2.0
        self.out_of_range = out_of_range
        self.action_space = spaces.Box(-1.0, 1.0, low.shape, np.float32)
        self.clip_steps = 0
        self._clipped = False

    def action(self, action: ArrayLike) -> NDArray[np.float64]:
        a = np.asarray(action, dtype=np.float64)
        if a.shape != self.mid.shape:
            raise ValueError(f"action must have shape {self.mid.shape}, got {a.shape}")
        inside = bool((np.abs(a) <= 1.0).all())  # false for NaN too
        if not inside and not np.isfinite(a).all():
            raise ValueError(f"action contains NaN or inf: {a}")
        self._clipped = not inside
        if self._clipped:
            if self.out_of_range == "error":
                raise ValueError(f"action beyond [-1, 1] at {np.flatnonzero(np.abs(a) > 1.0)}")
            a = np.clip(a, -1.0, 1.0)
            self.clip_steps += 1
        return self.to_torque(a)

    def to_torque(self, action: ArrayLike) -> NDArray[np.float64]:
        """The torques of an action inside ``[-1, 1]`` (no check)."""
        return self.mid + self.half * np.asarray(action, dtype=np.float64)

    def to_action(self, torque: ArrayLike) -> NDArray[np.float64]:
        """The action of torques (the inverse of :meth:`to_torque`)."""
        return (np.asarray(torque, dtype=np.float64) - self.mid) / self.half

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        self.clip_steps = 0
        observation, info = self.env.reset(seed=seed, options=options)
        info.update(action_clipped=False, action_clip_steps=0)
        return observation, info

    def step(self, action: ArrayLike) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(self.action(action))
        info.update(action_clipped=self._clipped, action_clip_steps=self.clip_steps)
        return observation, reward, terminated, truncated, info


# ------------------------------------------------------------------------------- reward
@dataclass(frozen=True)
class DenseRewardConfig:
    """The dense reward's weights and scales (docs/learning.md §6). Rates are per second of
    simulated time (multiplied by the env's ``dt``), so an episode's return does not depend on
    ``frame_skip``; the progress and the penalties are per event.

    Attributes:
        alive: per s while up: falling early costs what the rest of the episode would pay.
        goal: per s at the goal, ``exp(-d / goal_scale_m)`` of it at a distance ``d``: twice
            ``alive``, so being at the goal matters more than staying up longer; a pull
            steepest at the goal (2 per s per m there; the benchmark's goal tolerance is 5 cm)
            and positive everywhere, so that no state makes a fall pay.
        goal_scale_m: m, the goal term's decay length (half the default 2 m drive).
        progress: per m of goal distance gained (the env's own ``reward_progress``).
        theta: per s per rad^2 of the body's lean ``theta`` (balance); small: driving needs a
            lean (the controllers lean up to 0.14 to 0.21 rad on the 2 m drive).
        speed_at_goal: per s per (m/s)^2 of the wheels' mean squared ground speed (rolling
            without slip: ``xd -+ psid`` times half the wheel separation), weighted by
            ``exp(-(d / stop_width_m)^2)``: stop at the goal (both wheels: neither drive nor
            turn there; a policy circling the goal is a local optimum), move freely away from
            it.
        stop_width_m: m, the width of that neighbourhood of the goal.
        spin: 3-D robots, per s per (rad/s)^2 of the heading rate ``psid``: turn to the goal,
            not on the spot (a policy that spins while it balances is a local optimum).
        posture: robots with an end effector, per s per (``ee_error`` / ``posture_scale_m``)^2:
            the hand held where it was at the reset (the benchmark's ``max_ee_error_m``).
        posture_scale_m: m, the hand's drift that costs ``posture`` per s.
        ctrl: per s per unit of ``sum((torque / limit)^2)`` (the env's effort).
        tray_tilt: tray tasks, per s per (tilt / 10 deg)^2 (the paper keeps the tray level).
        friction: tray tasks, per s per unit of ``cup_friction_use^2`` (1 = slipping).
        fall: once, on the step the robot is found fallen.
        cup_loss: once, on the step the cup is lost (tray tasks).
    """

    alive: float = 1.0
    goal: float = 2.0
    goal_scale_m: float = 1.0
    progress: float = 1.0
    theta: float = 1.0
    speed_at_goal: float = 1.0
    stop_width_m: float = 0.1
    spin: float = 0.1
    posture: float = 1.0
    posture_scale_m: float = 0.1
    ctrl: float = 0.1
    tray_tilt: float = 1.0
    friction: float = 1.0
    fall: float = 10.0
    cup_loss: float = 10.0

    def __post_init__(self) -> None:
        for name, value in dataclasses.asdict(self).items():
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"DenseRewardConfig.{name} must be finite and >= 0, got {value}")
        for name in ("goal_scale_m", "stop_width_m", "posture_scale_m"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"DenseRewardConfig.{name} must be positive")


class DenseReward(gym.Wrapper[Any, Any, Any, Any], gym.utils.RecordConstructorArgs):
    """Replace the env's reward with a dense reward on the benchmark's measures.

    Per step (``dt`` the env's step, ``d`` the goal distance after it, ``s2`` the wheels' mean
    squared ground speed ``xd^2 + (psid * b)^2`` with ``b`` half the wheel separation (planar:
    ``xd^2``), ``u = sum((torque / limit)^2)``):

    | term (``info``) | value |
    |---|---|
    | ``dense_alive`` | ``alive * dt`` unless fallen |
    | ``dense_goal`` | ``goal * exp(-d / goal_scale_m) * dt`` |
    | ``dense_progress`` | ``progress * (d_before - d)`` |
    | ``dense_theta`` | ``-theta * theta^2 * dt`` |
    | ``dense_speed_at_goal`` | ``-speed_at_goal * exp(-(d / stop_width_m)^2) * s2 * dt`` |
    | ``dense_spin`` | ``-spin * psid^2 * dt`` (3-D robots) |
    | ``dense_posture`` | ``-posture * (ee_error / posture_scale_m)^2 * dt`` (robots with an end effector) |
    | ``dense_ctrl`` | ``-ctrl * u * dt`` |
    | ``dense_tray_tilt`` | ``-tray_tilt * (tray_tilt_deg / 10)^2 * dt`` (tray tasks) |
    | ``dense_friction`` | ``-friction * cup_friction_use^2 * dt`` (tray tasks) |
    | ``dense_fall`` | ``-fall`` on the step found fallen |
    | ``dense_cup_loss`` | ``-cup_loss`` on the step the cup is first lost (off the tray, or the tray off the hand) |

    The terms sum to the reward; the env's own reward stays in ``info["env_reward"]``. It
    reads the torques it is given: wrap the env itself (below :class:`ScaledAction`).
    """

    def __init__(
        self, env: gym.Env[Any, Any], config: DenseRewardConfig = DenseRewardConfig()
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, config=config)
        gym.Wrapper.__init__(self, env)
        if (
            not isinstance(env.action_space, spaces.Box)
            or env.action_space != wip_env(env).action_space
        ):
            raise ValueError("DenseReward reads torques: wrap the wip-gym env itself")
        base = wip_env(env)
        self.config = config
        self._limit = np.maximum(
            np.abs(np.asarray(base.action_space.high, dtype=np.float64)), 1e-12
        )
        self._tray = bool(base.scene_options.tray)
        #: m, half the wheel separation: a wheel's ground speed is xd -+ psid times it
        self._half_track = base.robot.layout.wheel_separation / 2.0
        self._distance = 0.0
        self._cup_lost = False

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        observation, info = self.env.reset(seed=seed, options=options)
        self._distance = float(info["goal_distance"])
        self._cup_lost = False
        return observation, info

    def step(self, action: ArrayLike) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        w, dt = self.config, float(wip_env(self.env).dt)
        torque = np.asarray(action, dtype=np.float64)
        distance = float(info["goal_distance"])
        fallen = bool(info["fallen"])
        terms = {
            "dense_alive": 0.0 if fallen else w.alive * dt,
            "dense_goal": w.goal * math.exp(-distance / w.goal_scale_m) * dt,
            "dense_progress": w.progress * (self._distance - distance),
            "dense_theta": -w.theta * float(info["theta"]) ** 2 * dt,
            "dense_speed_at_goal": -w.speed_at_goal
            * math.exp(-((distance / w.stop_width_m) ** 2))
            * (float(info["xd"]) ** 2 + (float(info.get("psid", 0.0)) * self._half_track) ** 2)
            * dt,
            "dense_ctrl": -w.ctrl * float(np.sum(np.square(torque / self._limit))) * dt,
            "dense_fall": -w.fall if fallen else 0.0,
        }
        if "psid" in info:
            terms["dense_spin"] = -w.spin * float(info["psid"]) ** 2 * dt
        if "ee_error" in info:
            terms["dense_posture"] = -w.posture * (info["ee_error"] / w.posture_scale_m) ** 2 * dt
        if self._tray:
            terms["dense_tray_tilt"] = (
                -w.tray_tilt * (float(info["tray_tilt_deg"]) / 10.0) ** 2 * dt
            )
            terms["dense_friction"] = -w.friction * float(info["cup_friction_use"]) ** 2 * dt
            lost = not (info["cup_on_tray"] and info["tray_on_hand"])
            terms["dense_cup_loss"] = -w.cup_loss if lost and not self._cup_lost else 0.0
            self._cup_lost = self._cup_lost or lost
        self._distance = distance
        info.update(terms)
        info["env_reward"] = float(reward)
        return observation, float(sum(terms.values())), terminated, truncated, info


# --------------------------------------------------------------------------------- goals
class RandomGoal(gym.Wrapper[Any, Any, Any, Any], gym.utils.RecordConstructorArgs):
    """A goal drawn uniformly in the box ``[low, high]`` (world ``X`` or ``(X, Y)``; a planar
    robot's goal is ``X``) at every reset, passed as ``reset(options={"goal": ...})``. Its
    generator is seeded by a reset's ``seed`` (so a seeded reset draws the same goal) and goes
    on from there at the resets without one (a vector env's autoresets)."""

    def __init__(
        self, env: gym.Env[Any, Any], low: float | Sequence[float], high: float | Sequence[float]
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, low=low, high=high)
        gym.Wrapper.__init__(self, env)
        planar = wip_env(env).robot.layout.planar
        size = 1 if planar else 2
        lo = np.atleast_1d(np.asarray(low, dtype=np.float64))
        hi = np.atleast_1d(np.asarray(high, dtype=np.float64))
        if lo.shape != (size,) or hi.shape != (size,):
            raise ValueError(
                f"goal bounds must have {size} entries for this robot, got {lo.shape}, {hi.shape}"
            )
        if not (np.isfinite(lo).all() and np.isfinite(hi).all() and (lo <= hi).all()):
            raise ValueError(f"goal bounds must be finite with low <= high, got {lo}, {hi}")
        self.low, self.high = lo, hi
        self._rng = np.random.default_rng()

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        goal = self._rng.uniform(self.low, self.high)
        goal_option = float(goal[0]) if goal.shape == (1,) else tuple(float(g) for g in goal)
        return self.env.reset(seed=seed, options={**(options or {}), "goal": goal_option})


def wrap_for_learning(
    env: gym.Env[Any, Any],
    dense_reward: bool = True,
    goal_low: float | Sequence[float] | None = None,
    goal_high: float | Sequence[float] | None = None,
    wheel_angles: WheelAngles = "drop",
    out_of_range: OutOfRange = "clip",
    dtype: Any = np.float32,
    reward: DenseRewardConfig = DenseRewardConfig(),
) -> gym.Env[Any, Any]:
    """``env`` wrapped in the order the wrappers need: the dense reward on the torques, a
    random goal (when both bounds are given), the flat observation, the scaled action."""
    if isinstance(env.unwrapped, WIPEnv) is False:
        raise ValueError(f"expected a wip-gym env, got {type(env.unwrapped).__name__}")
    if dense_reward:
        env = DenseReward(env, reward)
    if (goal_low is None) != (goal_high is None):
        raise ValueError("give both goal_low and goal_high, or neither")
    if goal_low is not None and goal_high is not None:
        env = RandomGoal(env, goal_low, goal_high)
    env = NormalizedObservation(env, wheel_angles, dtype)
    return ScaledAction(env, out_of_range)
