"""The decoupled controllers' upper-body hold, taking over from the reset state.

``PostureHold`` (``controllers.low_level.posture``) holds each body joint at its reset position
with zero velocity. The reset gives the joints velocities (``reset_noise_scale``, 0.01 rad/s),
and a hold toward zero velocity stops them in one control step: ``decoupled-mpc``'s stiff hold
(20 Hz) asks 2 zeta w 0.01 = 2.5 rad/s^2 of every joint at once. :class:`StoppingHold` holds
the joints on a reference instead, :class:`VelocityStop`: it starts at the reset's joint
positions and velocities with zero acceleration and brings the velocities to zero along a
minimum-jerk profile over ``stop_time_s``, then stays where the stop ends (``q0 + v0 T / 2``),
as a brake would. The PD acts on the error from the reference, which is zero at the reset, and
the reference's acceleration is fed forward; after the stop the hold is ``PostureHold``'s,
about the stop's end. Measured effect: docs/controllers.md §3.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from controllers.low_level.posture import PostureHold
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]


@dataclass(frozen=True)
class VelocityStop:
    """``q(t)``, ``qd(t)``, ``qdd(t)`` from ``(position, velocity)`` at ``t = 0`` to rest at
    ``t = duration``: ``qd = v0 (1 - m(s))`` with ``s = t / T`` and ``m(s) = 10 s^3 - 15 s^4 +
    6 s^5`` (the minimum-jerk unit profile, Flash and Hogan 1985), so the acceleration is zero
    at both ends and peaks at ``1.875 |v0| / T`` mid-stop; the position ends at ``q0 + v0 T /
    2``. ``duration = 0`` is the step stop: ``(q0, 0, 0)`` from ``t = 0``."""

    position: Array
    velocity: Array
    duration: float

    def __post_init__(self) -> None:
        if not (np.isfinite(self.duration) and self.duration >= 0):
            raise ValueError(f"duration must be finite and >= 0, got {self.duration!r}")
        if self.position.shape != self.velocity.shape or self.position.ndim != 1:
            raise ValueError(
                f"position and velocity must be 1-D of one shape, got {self.position.shape} "
                f"and {self.velocity.shape}"
            )

    def __call__(self, t: float) -> tuple[Array, Array, Array]:
        """Position, velocity and acceleration at ``t`` (s since the reset, ``t >= 0``)."""
        if not t >= 0:
            raise ValueError(f"t must be >= 0, got {t!r}")
        q0, v0, T = self.position, self.velocity, self.duration
        if T == 0.0:
            return q0, np.zeros_like(v0), np.zeros_like(v0)
        s = min(t / T, 1.0)
        travelled = s - (2.5 * s**4 - 3.0 * s**5 + s**6)  # integral of 1 - m over [0, s]
        remaining = 1.0 - (10.0 * s**3 - 15.0 * s**4 + 6.0 * s**5)
        slope = (30.0 * s**2 - 60.0 * s**3 + 30.0 * s**4) / T  # dm/dt
        return q0 + v0 * (T * travelled), v0 * remaining, -v0 * slope


class StoppingHold(PostureHold):
    """``PostureHold`` on a :class:`VelocityStop` from the reset state (module docstring).

    ``torques(robot, base_acceleration, t=t)``: as ``PostureHold.torques`` with the error taken
    from the reference at ``t`` (s since the reset) and its acceleration fed forward; the
    deviation tracked (``last_deviation``, ``max_deviation``) is from the reference."""

    def __init__(
        self, frequency_hz: float = 5.0, damping_ratio: float = 1.0, stop_time_s: float = 0.1
    ) -> None:
        super().__init__(frequency_hz, damping_ratio)
        if not (np.isfinite(stop_time_s) and stop_time_s >= 0):
            raise ValueError(f"stop_time_s must be finite and >= 0, got {stop_time_s!r}")
        self.stop_time_s = stop_time_s
        self.stop: VelocityStop | None = None

    def reset(self, robot: RobotModel) -> None:
        super().reset(robot)
        first = robot.layout.index_q1 + 1
        self.stop = VelocityStop(self.posture.copy(), robot.nu[first:].copy(), self.stop_time_s)

    def torques(
        self,
        robot: RobotModel,
        base_acceleration: NDArray[np.float64] | None = None,
        t: float | None = None,
    ) -> NDArray[np.float64]:
        """Torques of the body joints at ``t`` s after the reset (required)."""
        if self.stop is None:
            raise RuntimeError("StoppingHold: reset() first")
        if t is None:
            raise ValueError("StoppingHold.torques needs t, the time since the reset")
        first = self._first
        q_ref, qd_ref, qdd_ref = self.stop(t)
        error = robot.q[first:] - q_ref
        rate_error = robot.nu[first:] - qd_ref
        self._track(error)
        if base_acceleration is None:
            inertia = self.kp / self._w**2
            return robot.h[first:] + inertia * qdd_ref - self.kp * error - self.kd * rate_error
        base_acceleration = np.asarray(base_acceleration, dtype=float)
        if base_acceleration.shape != (first,):
            raise ValueError(
                f"base_acceleration must have {first} entries, got {base_acceleration.shape}"
            )
        w, zeta = self._w, self.damping_ratio
        qdd = qdd_ref - w**2 * error - 2.0 * zeta * w * rate_error
        A = robot.A
        return A[first:, :first] @ base_acceleration + A[first:, first:] @ qdd + robot.h[first:]
