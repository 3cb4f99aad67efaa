"""Holding the upper body at a posture: joint PD with gravity (bias) compensation.

The baselines' upper body (reference/krang_facts.md 5.2: the real robot held its arms by the
Schunk modules' position control; the authors' simulation locked them): ``tau_j = h_j -
Kp (q_j - q_j0) - Kd qd_j`` on every body joint above the base pitch, with ``h`` the
minimal-coordinate bias (gravity, Coriolis, friction) and gains set from each joint's inertia
at reset, ``Kp = A_jj w^2``, ``Kd = 2 zeta A_jj w``. Blind to balance: no term couples it to the
wheels.
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

    def reset(self, robot: RobotModel) -> None:
        self._first = robot.layout.index_q1 + 1
        self.posture = robot.q[self._first :].copy()
        inertia = np.diag(robot.A)[self._first :]
        w = 2 * np.pi * self.frequency_hz
        self.kp = inertia * w**2
        self.kd = 2 * self.damping_ratio * inertia * w

    def torques(self, robot: RobotModel) -> NDArray[np.float64]:
        """Torques of the body joints (``robot.layout.joint_actuators`` order)."""
        first = self._first
        error = robot.q[first:] - self.posture
        return robot.h[first:] - self.kp * error - self.kd * robot.nu[first:]
