"""Smooth references that take a WIP to its goal (the decoupled baseline's).

A minimum-jerk profile (Flash and Hogan 1985) moves a coordinate from 0 to ``D`` in ``T`` with
zero velocity and acceleration at both ends; its peak acceleration is ``10/sqrt(3) D / T^2``, so
``T`` is chosen from an acceleration bound. In 3-D the robot first turns in place to face the
goal, then drives to it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PEAK_ACCELERATION = 10.0 / np.sqrt(3.0)  # of the unit minimum-jerk profile, times D / T^2


@dataclass(frozen=True)
class MinimumJerk:
    """``p(t)`` from 0 to ``distance`` over ``duration`` starting at ``start``."""

    distance: float
    duration: float
    start: float = 0.0

    @classmethod
    def with_peak_acceleration(
        cls, distance: float, max_acceleration: float, start: float = 0.0
    ) -> MinimumJerk:
        if max_acceleration <= 0:
            raise ValueError(f"max_acceleration must be positive, got {max_acceleration}")
        duration = float(np.sqrt(PEAK_ACCELERATION * abs(distance) / max_acceleration))
        return cls(distance, max(duration, 1e-9), start)

    @property
    def end(self) -> float:
        return self.start + self.duration

    def __call__(self, t: float) -> tuple[float, float, float]:
        """Position, velocity and acceleration at time ``t``."""
        s = min(max((t - self.start) / self.duration, 0.0), 1.0)
        d, T = self.distance, self.duration
        position = d * (10 * s**3 - 15 * s**4 + 6 * s**5)
        if s <= 0.0 or s >= 1.0:
            return position, 0.0, 0.0
        velocity = d / T * (30 * s**2 - 60 * s**3 + 30 * s**4)
        acceleration = d / T**2 * (60 * s - 180 * s**2 + 120 * s**3)
        return position, velocity, acceleration


@dataclass(frozen=True)
class GoalReference:
    """Turn to face the goal, then drive to it: ``psi(t)`` and the distance rolled ``x(t)``.

    Attributes:
        heading: minimum-jerk profile of ``psi`` (zero distance for a goal straight ahead).
        drive: minimum-jerk profile of ``x`` (odometry), starting when the turn ends.
        x0, psi0: odometry and heading at the start.
    """

    heading: MinimumJerk
    drive: MinimumJerk
    x0: float = 0.0
    psi0: float = 0.0

    @classmethod
    def to_goal(
        cls,
        start_xy: np.ndarray,
        start_heading: float,
        goal_xy: np.ndarray,
        *,
        x0: float,
        max_acceleration: float,
        max_spin_acceleration: float,
        planar: bool,
    ) -> GoalReference:
        delta = np.asarray(goal_xy, dtype=float) - np.asarray(start_xy, dtype=float)
        if planar:
            turn = 0.0
            distance = float(delta[0])
        else:
            distance = float(np.hypot(*delta))
            turn = (
                0.0
                if distance < 1e-9
                else float(np.angle(np.exp(1j * (np.arctan2(delta[1], delta[0]) - start_heading))))
            )
        heading = MinimumJerk.with_peak_acceleration(turn, max_spin_acceleration)
        drive = MinimumJerk.with_peak_acceleration(
            distance, max_acceleration, start=heading.end if abs(turn) > 1e-9 else 0.0
        )
        return cls(heading, drive, x0, start_heading)

    @property
    def end(self) -> float:
        return max(self.heading.end, self.drive.end)

    def __call__(self, t: float) -> dict[str, float]:
        x, xd, xdd = self.drive(t)
        psi, psid, psidd = self.heading(t)
        return {
            "x": self.x0 + x,
            "xd": xd,
            "xdd": xdd,
            "psi": self.psi0 + psi,
            "psid": psid,
            "psidd": psidd,
        }
