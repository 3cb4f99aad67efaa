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

from wip_gym.envs.draws import Draws
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


def rotation_quat(x: float, y: float, z: float) -> tuple[float, float, float, float]:
    """The unit quaternion ``(w, x, y, z)`` of the rotation vector ``(x, y, z)`` (axis times
    angle, rad)."""
    angle = math.sqrt(x * x + y * y + z * z)
    if angle == 0.0:
        return (1.0, 0.0, 0.0, 0.0)
    k = math.sin(angle / 2) / angle
    return (math.cos(angle / 2), k * x, k * y, k * z)


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
        self._attitude_bias_floats: tuple[float, ...] = (0.0, 0.0)
        self._gyro_bias_floats: tuple[float, ...] = (0.0, 0.0, 0.0)
        self._yaw_drift = 0.0
        self._rng = np.random.default_rng(0)
        self._white = Draws(self._rng, lambda r, n: r.standard_normal((n, 6)))
        #: the last observation's errors, for inspection: attitude (roll, pitch, yaw) about
        #: the heading frame (rad), gyro (rad/s, the base frame; planar: pitch in [1]),
        #: encoder readings minus the true angles (rad), wheels first
        self.last_attitude_error: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.last_gyro_error: tuple[float, float, float] = (0.0, 0.0, 0.0)
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
        self._white = Draws(rng, lambda r, n: r.standard_normal((n, 6)))
        # roll and pitch; the heading's error grows from the gyro's bias
        self._attitude_bias_floats = tuple((rng.normal(0.0, 1.0, 2) * f.attitude_bias).tolist())
        self._gyro_bias_floats = tuple((rng.normal(0.0, 1.0, 3) * f.gyro_bias).tolist())
        self._offsets = rng.uniform(-0.5, 0.5, len(self._steps)) * self._steps
        self._yaw_drift = 0.0
        angles = qpos[self._encoder_qpos]
        self._previous = self._read(angles - qvel[self._encoder_dof] * self.dt)

    def sense(self, qpos: Array, qvel: Array, first: bool = False) -> tuple[Array, Array]:
        """The sensed ``(qpos, qvel)`` of the true robot state (new arrays). ``first``: the
        reset's observation (the heading's drift starts there). Scalar arithmetic for the IMU
        (a dozen small NumPy calls cost more than the step's physics)."""
        lay, f = self.layout, self.figures
        qpos = qpos.copy()
        qvel = qvel.copy()
        n0, n1, n2, n3, n4, n5 = self._white()
        bx, by, bz = self._gyro_bias_floats
        gyro = (bx + n3 * f.gyro_noise, by + n4 * f.gyro_noise, bz + n5 * f.gyro_noise)
        roll_bias, pitch_bias = self._attitude_bias_floats
        noise = f.attitude_noise
        roll, pitch, yaw = roll_bias + n0 * noise, pitch_bias + n1 * noise, n2 * noise
        o, v = lay.root_qpos, lay.root_dof
        encoders, dofs = self._encoder_qpos, self._encoder_dof
        angles = qpos[encoders]
        readings = self._read(angles)
        rates = (readings - self._previous) / self.dt
        encoder_error = readings - angles
        self._previous = readings
        if lay.planar:
            roll = yaw = 0.0
            gyro = (0.0, gyro[1], 0.0)
            qpos[o + 2] += pitch
            # odometry: r times the error of the absolute wheel angle
            e_left, e_right = encoder_error[0], encoder_error[1]
            r_left, r_right = rates[0] - qvel[dofs[0]], rates[1] - qvel[dofs[1]]
            qpos[o] += lay.wheel_radius * (0.5 * (e_left + e_right) + pitch)
            qvel[v] += lay.wheel_radius * (0.5 * (r_left + r_right) + gyro[1])
            qvel[v + 2] += gyro[1]
        else:
            w, x, y, z = qpos[o + 3 : o + 7].tolist()
            if not first:
                # the integrated gyro's heading: its bias's world-z rate over the step (the
                # base rotation's third row times the bias)
                self._yaw_drift += (
                    2 * (x * z - w * y) * bx
                    + 2 * (y * z + w * x) * by
                    + (1 - 2 * (x * x + y * y)) * bz
                ) * self.dt
            yaw += self._yaw_drift
            psi = math.atan2(-2 * (x * y - w * z), 1 - 2 * (x * x + z * z))
            c, s = math.cos(psi), math.sin(psi)
            ew, ex, ey, ez = rotation_quat(c * roll - s * pitch, s * roll + c * pitch, yaw)
            qpos[o + 3 : o + 7] = (
                ew * w - ex * x - ey * y - ez * z,
                ew * x + ex * w + ey * z - ez * y,
                ew * y - ex * z + ey * w + ez * x,
                ew * z + ex * y - ey * x + ez * w,
            )
            qvel[v + 3] += gyro[0]
            qvel[v + 4] += gyro[1]
            qvel[v + 5] += gyro[2]
        qpos[encoders] = readings
        qvel[dofs] = rates
        self.last_attitude_error = (roll, pitch, yaw)
        self.last_gyro_error = gyro
        self.last_encoder_error = encoder_error
        return qpos, qvel
