"""Holding the upper body at a posture: joint PD with gravity (bias) compensation.

The baselines' upper body (docs/AUTHORS_CONFIG.md §5.2: the real robot held its arms by the
Schunk modules' position control; the authors' simulation locked them): ``tau_j = h_j -
Kp (q_j - q_j0) - Kd qd_j`` on every body joint above the base pitch, with ``h`` the
minimal-coordinate bias (gravity, Coriolis, friction) and gains set from each joint's inertia
at reset, ``Kp = A_jj w^2``, ``Kd = 2 zeta A_jj w``. Blind to balance: no term couples it to the
wheels.

With ``base_acceleration`` (``decoupled-mpc``, as close to the authors' locked joints as the
torque limits allow; docs/AUTHORS_CONFIG.md §5.1) it is computed torque: ``tau_j = A_jb
nu_dot_b + A_jj qdd_j* + h_j`` over the whole body row of ``A nu_dot + h = B tau``, with the
base's expected acceleration ``nu_dot_b`` (``xdd``, ``psidd``, ``q1dd``) as feed-forward and
``qdd_j* = -w^2 (q_j - q_j0) - 2 zeta w qd_j`` a stiff PD; the joints then ride the base's
acceleration instead of lagging it.

Either way the largest deviation of any held joint from its posture is kept
(``max_deviation``, rad): how far from locked the joints were.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wip_gym.robot_model import RobotModel


class PostureHold:
    """Joint PD + bias compensation around the posture the robot had at ``reset``."""

    def __init__(self, frequency_hz: float = 5.0, damping_ratio: float = 1.0) -> None:
        if frequency_hz <= 0 or damping_ratio <= 0:
            raise ValueError("posture frequency and damping ratio must be positive")
        self.frequency_hz = frequency_hz
        self.damping_ratio = damping_ratio
        self.max_deviation = 0.0
        self.last_deviation = 0.0

    def reset(self, robot: RobotModel) -> None:
        self._first = robot.layout.index_q1 + 1
        self.posture = robot.q[self._first :].copy()
        inertia = np.diag(robot.A)[self._first :]
        w = 2 * np.pi * self.frequency_hz
        self._w = w
        self.kp = inertia * w**2
        self.kd = 2 * self.damping_ratio * inertia * w
        self.max_deviation = 0.0
        self.last_deviation = 0.0

    def _track(self, error: NDArray[np.float64]) -> None:
        deviation = float(np.max(np.abs(error), initial=0.0))
        self.last_deviation = deviation
        self.max_deviation = max(self.max_deviation, deviation)

    def torques(
        self, robot: RobotModel, base_acceleration: NDArray[np.float64] | None = None
    ) -> NDArray[np.float64]:
        """Torques of the body joints (``robot.layout.joint_actuators`` order). Without
        ``base_acceleration``: PD + bias. With it (the minimal accelerations of the base,
        ``[xdd, q1dd]`` planar or ``[xdd, psidd, q1dd]``): computed torque (module
        docstring)."""
        first = self._first
        error = robot.q[first:] - self.posture
        self._track(error)
        if base_acceleration is None:
            return robot.h[first:] - self.kp * error - self.kd * robot.nu[first:]
        base_acceleration = np.asarray(base_acceleration, dtype=float)
        if base_acceleration.shape != (first,):
            raise ValueError(
                f"base_acceleration must have {first} entries, got {base_acceleration.shape}"
            )
        w, zeta = self._w, self.damping_ratio
        qdd = -(w**2) * error - 2.0 * zeta * w * robot.nu[first:]
        A = robot.A
        return A[first:, :first] @ base_acceleration + A[first:, first:] @ qdd + robot.h[first:]
