"""What the robot's sensors report: the observation's ``qpos``/``qvel`` as an IMU and encoders
would give them (the ``sensor_noise`` env argument; docs/realism.md §2).

:class:`SensorModel` holds each sensor's figures at ``sensor_noise = 1`` with their sources;
``sensor_noise`` scales every standard deviation, bias and encoder step (0: the exact state,
and nothing is drawn). How each sensor maps onto the observation:

* **IMU attitude** (base link; 3-D: the free joint's quaternion, planar: ``root_pitch``). An
  attitude error ``(roll, pitch, yaw)`` about the heading frame's axes (x along the heading,
  y the wheel axis, z up) rotates the true attitude: ``q_obs = exp(e_world / 2) * q_true`` with
  ``e_world = Rz(psi) e``, so the observed base pitch is the true one plus the pitch error.
  Roll and pitch errors: a bias drawn per episode, ``N(0, attitude_bias_rad)``, plus white noise
  per sample, ``N(0, attitude_noise_rad)``. Yaw (3-D): the heading of an integrated gyro, its
  error the integral of the gyro bias's world-z component since the reset, plus the same white
  noise.
* **Gyro** (the base's angular velocity; 3-D: the free joint's body-frame rate, planar:
  ``root_pitch``'s rate): plus a per-episode bias ``N(0, gyro_bias_rad_s)`` per axis and white
  noise ``N(0, gyro_noise_density * sqrt(1 / (2 dt)))``, the datasheet's density over the
  Nyquist band of the control step ``dt``.
* **Encoders** (the wheel hinges and every body joint): the angle quantised at
  ``2 pi / counts`` with the encoder's zero at a per-episode offset ``U(-step/2, step/2)``
  (so the error is within half a step and, as the angle moves, uniform with standard deviation
  ``step / sqrt(12)``); the rate is the backward difference of two readings one control step
  apart (at the reset the earlier reading is of the state one step before at constant rate).
* **Odometry** (planar ``root_x`` and its rate): the true value plus the wheel radius times the
  error of the absolute wheel angle (the mean encoder error of the two wheels plus the IMU
  pitch error), as the rolled distance ``r (phi + q1)`` of docs/DESIGN.md §4 would carry it. In
  3-D ``x`` is wheel odometry already (``RobotModel`` reads it from the wheels and the IMU).
* **Not sensed**, left exact: the 3-D base position and linear velocity (no sensor on the
  robot gives them; the shipped controllers read them only for the axle's ``X0, Y0`` and the
  goal's direction), the planar ``root_z`` and its rate, the goal and the cup's pose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wip_gym.robot_model import RobotLayout

Array = NDArray[np.float64]


@dataclass(frozen=True)
class SensorModel:
    """Each sensor's figures at ``sensor_noise = 1`` (docs/realism.md §2 for the sources).

    Attributes:
        attitude_bias_rad: standard deviation of the IMU's roll and pitch error held for an
            episode (rad): 0.3 deg, "a bias of 0.05 to 0.5 deg" of a filtered MEMS attitude
            (gyro bias times the filter's time constant, and the accelerometer's offset).
        attitude_noise_rad: standard deviation of the attitude's white noise per sample (rad):
            5e-5 rad (0.003 deg), a complementary filter's budget on a TDK ICM-42688-P at a
            0.5 s time constant.
        gyro_bias_rad_s: standard deviation of each gyro axis's bias held for an episode
            (rad/s): 0.1 deg/s, the residual turn-on bias of a consumer MEMS gyro.
        gyro_noise_density: the gyro's white-noise density (rad/s/sqrt(Hz)): the ICM-42688-P's
            2.8 mdps/sqrt(Hz).
        wheel_encoder_counts: counts per wheel revolution: Krang's 4000-count motor encoder
            behind its 15:1 gearbox, 60,000.
        joint_encoder_counts: counts per body-joint revolution: a 4000-count motor encoder
            behind the smallest gear ratio of Krang's Schunk modules (300), 1,200,000 (the
            modules' encoder is not in our sources: assumed like the wheels').
    """

    attitude_bias_rad: float = math.radians(0.3)
    attitude_noise_rad: float = 5e-5
    gyro_bias_rad_s: float = math.radians(0.1)
    gyro_noise_density: float = 4.9e-5
    wheel_encoder_counts: int = 60_000
    joint_encoder_counts: int = 4000 * 300

    def __post_init__(self) -> None:
        for name in (
            "attitude_bias_rad",
            "attitude_noise_rad",
            "gyro_bias_rad_s",
            "gyro_noise_density",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
        for name in ("wheel_encoder_counts", "joint_encoder_counts"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)!r}")

    def scaled(self, scale: float, dt: float) -> SensorFigures:
        """The figures in use at ``sensor_noise = scale`` and control step ``dt`` (s)."""
        return SensorFigures(
            attitude_bias=scale * self.attitude_bias_rad,
            attitude_noise=scale * self.attitude_noise_rad,
            gyro_bias=scale * self.gyro_bias_rad_s,
            gyro_noise=scale * self.gyro_noise_density * math.sqrt(1.0 / (2.0 * dt)),
            wheel_step=scale * 2.0 * math.pi / self.wheel_encoder_counts,
            joint_step=scale * 2.0 * math.pi / self.joint_encoder_counts,
        )


@dataclass(frozen=True)
class SensorFigures:
    """Standard deviations (rad, rad/s) and encoder steps (rad) as applied."""

    attitude_bias: float
    attitude_noise: float
    gyro_bias: float
    gyro_noise: float
    wheel_step: float
    joint_step: float


def _quat_mul(a: Array, b: Array) -> Array:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def rotation_quat(vector: Array) -> Array:
    """The unit quaternion of the rotation vector ``vector`` (axis times angle, rad)."""
    angle = float(np.linalg.norm(vector))
    if angle == 0.0:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate(([math.cos(angle / 2)], math.sin(angle / 2) * vector / angle))


def _base_rotation(quat: Array) -> Array:
    w, x, y, z = quat
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


class Sensors:
    """The sensors of one robot: :meth:`begin` at each reset (draws the episode's biases and
    encoder offsets), :meth:`sense` per observation (draws the white noise)."""

    def __init__(self, layout: RobotLayout, figures: SensorFigures, dt: float) -> None:
        self.layout = layout
        self.figures = figures
        self.dt = dt
        lay = layout
        self._encoder_qpos = np.array([*lay.wheel_qpos, *lay.body_qpos], dtype=np.int64)
        self._encoder_dof = np.array([*lay.wheel_dof, *lay.body_dof], dtype=np.int64)
        self._steps = np.array([figures.wheel_step] * 2 + [figures.joint_step] * len(lay.body_qpos))
        self._offsets = np.zeros(len(self._steps))
        self._previous = np.zeros(len(self._steps))
        self._attitude_bias = np.zeros(3)
        self._gyro_bias = np.zeros(3)
        self._yaw_drift = 0.0
        self._rng = np.random.default_rng(0)
        #: the last observation's errors, for inspection and tests: attitude (roll, pitch,
        #: yaw) about the heading frame (rad), gyro (rad/s, the base frame; planar: pitch in
        #: [1]), encoder readings minus the true angles (rad), wheels first
        self.last_attitude_error = np.zeros(3)
        self.last_gyro_error = np.zeros(3)
        self.last_encoder_error = np.zeros(len(self._steps))

    def _read(self, angles: Array) -> Array:
        steps, offsets = self._steps, self._offsets
        readings: Array = steps * np.round((angles - offsets) / steps) + offsets
        return readings

    def begin(self, rng: np.random.Generator, qpos: Array, qvel: Array) -> None:
        """A new episode from the true state ``(qpos, qvel)``: draw the biases and the encoder
        offsets from ``rng`` (the sensors' own stream, kept for :meth:`sense`)."""
        f = self.figures
        self._rng = rng
        self._attitude_bias = rng.normal(0.0, 1.0, 3) * f.attitude_bias
        self._attitude_bias[2] = 0.0  # the heading's error grows from the gyro's bias
        self._gyro_bias = rng.normal(0.0, 1.0, 3) * f.gyro_bias
        self._offsets = rng.uniform(-0.5, 0.5, len(self._steps)) * self._steps
        self._yaw_drift = 0.0
        angles = qpos[self._encoder_qpos]
        self._previous = self._read(angles - qvel[self._encoder_dof] * self.dt)

    def sense(self, qpos: Array, qvel: Array, first: bool = False) -> tuple[Array, Array]:
        """The sensed ``(qpos, qvel)`` of the true robot state (new arrays). ``first``: the
        reset's observation (the heading's drift starts there)."""
        lay, f, rng = self.layout, self.figures, self._rng
        qpos = qpos.copy()
        qvel = qvel.copy()
        white = rng.standard_normal(6)
        gyro_error = self._gyro_bias + white[3:] * f.gyro_noise
        attitude_error = self._attitude_bias + white[:3] * f.attitude_noise
        o, v = lay.root_qpos, lay.root_dof
        if lay.planar:
            attitude_error[0] = attitude_error[2] = 0.0
            gyro_error[0] = gyro_error[2] = 0.0
        else:
            quat = qpos[o + 3 : o + 7]
            rotation = _base_rotation(quat)
            if not first:
                # the integrated gyro's heading: its bias's world-z rate over the step
                self._yaw_drift += float(rotation[2] @ self._gyro_bias) * self.dt
            attitude_error[2] += self._yaw_drift
        angles = qpos[self._encoder_qpos]
        readings = self._read(angles)
        rates = (readings - self._previous) / self.dt
        encoder_error = readings - angles
        self._previous = readings
        if lay.planar:
            pitch_error = attitude_error[1]
            rate_error = gyro_error[1]
            qpos[o + 2] += pitch_error
            qvel[v + 2] += rate_error
            # odometry: r times the error of the absolute wheel angle
            rolled = 0.5 * (encoder_error[0] + encoder_error[1]) + pitch_error
            wheel_rates = qvel[self._encoder_dof[:2]]
            rolled_rate = 0.5 * float(np.sum(rates[:2] - wheel_rates)) + rate_error
            qpos[o] += lay.wheel_radius * rolled
            qvel[v] += lay.wheel_radius * rolled_rate
        else:
            psi = math.atan2(-rotation[0, 1], rotation[1, 1])
            c, s = math.cos(psi), math.sin(psi)
            ex, ey, ez = attitude_error
            world = np.array([c * ex - s * ey, s * ex + c * ey, ez])
            qpos[o + 3 : o + 7] = _quat_mul(rotation_quat(world), quat)
            qvel[v + 3 : v + 6] += gyro_error
        qpos[self._encoder_qpos] = readings
        qvel[self._encoder_dof] = rates
        self.last_attitude_error = attitude_error
        self.last_gyro_error = gyro_error
        self.last_encoder_error = encoder_error
        return qpos, qvel
