"""Where the upright controller holds the tray: tilted into the plan's acceleration, its place
kept by the tilt (docs/upright.md §3).

An object on a tray feels no tangential force when the tray's normal points along the specific
force ``a - g`` of the tray's acceleration ``a``. The upright controller asks the task QP for a
tray whose tangential specific force is zero (a task of the QP, ``ObjectBalance.tangential``):
with the tray's tilt given at an instant, that fixes the tray's horizontal acceleration to the
one its tilt allows, ``g tan(tilt)``. The tilt itself is steered here, as a cascade:

* **inner**: the tray's target tilt is the direction of ``a_d - g`` with ``a_d`` the horizontal
  acceleration the tray should have, and the hand's orientation tasks track it;
* **outer**: ``a_d = a_plan(t + lead) - k_p e - k_v e'``: the offline plan's acceleration of the
  axle a little ahead (the tray held over the axle moves with it), corrected by the tray's drift
  ``e`` from its place over the axle (axle frame, horizontal). If the tilt lags, the tray
  accelerates less than the axle, falls behind, and the loop tilts it further.

The plan, not the MPC's prediction: the plan is computed once and does not react to the body,
whereas a target from the MPC's latest prediction closes a loop through the arm's motion, the
body's centre of mass and the next MPC solve, which oscillated in closed loop (docs/upright.md
§3 has the measurements). The tray turns about its plate's centre, rigidly with every hand that
holds it (Krang's two grippers hold a free tray between them).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from controllers.high_level.planning import Plan
from wip_gym.scene import GRAVITY

Array = NDArray[np.float64]


def tilt_toward(acceleration: Array, max_tilt_deg: float) -> Array:
    """Rotation (axle frame) taking ``e_z`` to the direction of ``a - g`` (``a`` the horizontal
    acceleration ``(forward, lateral)``, ``g = (0, 0, -9.81)``), the tilt bounded."""
    specific = np.array([acceleration[0], acceleration[1], GRAVITY])
    n = specific / np.linalg.norm(specific)
    axis = np.array([-n[1], n[0], 0.0])  # e_z x n
    s = math.hypot(n[0], n[1])
    angle = min(np.arctan2(s, n[2]), np.radians(max_tilt_deg))
    if s < 1e-12:
        return np.eye(3)
    quat = np.zeros(4)
    mujoco.mju_axisAngle2Quat(quat, axis / s, angle)
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, quat)
    return R.reshape(3, 3)


def plan_acceleration(plan: Plan, t: float) -> tuple[float, float]:
    """The axle's acceleration the plan's reference holds at time ``t`` (s), in the axle
    frame: forward ``dxd/dt`` (the difference of the reference's speeds over the step holding
    ``t``: the plan, its continuation past ``t_f``, then rest) and lateral ``xd psid`` (3-D; 0
    planar). Zero before the start."""
    i = int(np.floor(t / plan.dt))
    if i < 0:
        return 0.0, 0.0
    now, ahead = plan.state(i), plan.state(i + 1)
    forward = float((ahead[3] - now[3]) / plan.dt)  # xd is column 3 of both state layouts
    if plan.planar:  # [theta, thetad, x, xd]
        return forward, 0.0
    return forward, float(now[3] * now[4])  # [x, psi, theta, xd, psid, thetad, X0, Y0]


@dataclass(frozen=True)
class TrayGains:
    """The cascade's settings (docs/upright.md §3 and §5 measured them on PlanarTray-v0's
    aggressive drive).

    Attributes:
        lead: how far ahead the plan's acceleration is read (s): the orientation tasks' lag
            and the body's. 0.25: at friction 0.05 the mean time to goal is 3.75 s; 0.1 to 0.2
            (kp 1, kv 1.5) leaves some seeds about the goal past 4.2 s, 0.3 raised one seed's
            p99 friction use to 0.84 (docs/upright.md §5).
        kp, kv: the outer loop's gains on the tray's drift over the axle (1/s^2, 1/s). 1 and
            1.5: a stiffer loop oscillates with the body about the goal (kp 4, kv 4: time to
            goal 5.3 to 7.9 s) or drops the cup (kv 8); a softer one let the body fall in one
            seed (kp 1, kv 1). The tray then leaves its place over the axle by up to 23 cm
            during the drive (docs/upright.md §5).
        max_tilt_deg: the tilt's bound (deg).
        level_s: a tray that rests tilted at reset is levelled over this time (s), along a
            smooth step (a free tray on Krang's finger plates rests 3 to 4 deg off level: turned
            level at once, the turn's own acceleration slid the cup within 20 ms).
    """

    lead: float = 0.25
    kp: float = 1.0
    kv: float = 1.5
    max_tilt_deg: float = 35.0
    level_s: float = 1.0

    def level_fraction(self, t: float) -> float:
        """How far the levelling has gone at ``t`` s after reset: ``3 u^2 - 2 u^3``,
        ``u = t / level_s`` within [0, 1]."""
        if self.level_s <= 0.0:
            return 1.0
        u = min(max(t / self.level_s, 0.0), 1.0)
        return u * u * (3.0 - 2.0 * u)

    def __post_init__(self) -> None:
        for name in ("lead", "kp", "kv", "level_s"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {getattr(self, name)!r}")
        if not 0 < self.max_tilt_deg < 90:
            raise ValueError(f"max_tilt_deg must be in (0, 90), got {self.max_tilt_deg!r}")


def leveling_rotation(normal: Array, fraction: float = 1.0) -> Array:
    """The smallest rotation taking the unit vector ``normal`` to ``e_z`` (``fraction`` 1), or
    ``fraction`` (0 to 1) of the way: about the same axis, by the angle whose tangent is
    ``fraction`` times the full turn's."""
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    return tilt_toward(np.array([-n[0], -n[1]]) * fraction * GRAVITY / n[2], 90.0)


class TrayReference:
    """The targets of the hands that hold the tray (module docstring): made from their reset
    poses in the axle frame, the plate centre's and the plate's normal, then :meth:`targets`
    each control step. A tray that rests tilted on the hand at reset (a free tray on Krang's
    finger plates, 2.9 deg) is levelled first: the targets turn by ``R_tilt R_level``, with
    ``R_level`` the smallest rotation taking the reset normal to the vertical."""

    def __init__(
        self,
        pivot: Array,
        hand_positions: Sequence[Array],
        hand_rotations: Sequence[Array],
        gains: TrayGains,
        normal: Array = (0.0, 0.0, 1.0),
    ) -> None:
        if len(hand_positions) != len(hand_rotations) or not hand_positions:
            raise ValueError("one reset position and rotation per hand, at least one hand")
        if not np.asarray(normal, dtype=float)[2] > 0:
            raise ValueError(f"the plate's normal must point up, got {normal!r}")
        self._normal = np.asarray(normal, dtype=float)
        self.level = leveling_rotation(self._normal)
        self.pivot = np.array(pivot, dtype=float)
        self._arms = [np.array(p, dtype=float) - self.pivot for p in hand_positions]
        self._rotations = [np.array(R, dtype=float) for R in hand_rotations]
        self.gains = gains
        #: the last target tilt (a rotation in the axle frame)
        self.tilt = np.eye(3)

    def desired_acceleration(
        self, plan_acceleration: tuple[float, float], drift: Array, drift_rate: Array
    ) -> Array:
        """``a_d`` (axle frame, horizontal): the plan's acceleration corrected by the tray's
        drift ``drift`` and its rate (the plate centre from its reset place, axle frame)."""
        g = self.gains
        return (
            np.array(plan_acceleration)
            - g.kp * np.asarray(drift[:2])
            - g.kv * np.asarray(drift_rate[:2])
        )

    def leveling(self, fraction: float) -> Array:
        """The levelling rotation ``fraction`` (0 to 1) of the way: about the same axis, by
        the angle whose tangent is ``fraction`` times the reset tilt's (1: :attr:`level`)."""
        if fraction >= 1.0:
            return self.level
        return leveling_rotation(self._normal, fraction)

    def targets(
        self,
        plan_acceleration: tuple[float, float],
        drift: Array,
        drift_rate: Array,
        level_fraction: float = 1.0,
    ) -> list[tuple[Array, Array]]:
        """Each hand's target ``(position, rotation)`` in the axle frame: its reset pose
        levelled and turned by the tilt toward ``a_d - g``, about the plate's centre at its
        reset place."""
        a = self.desired_acceleration(plan_acceleration, drift, drift_rate)
        self.tilt = tilt_toward(a, self.gains.max_tilt_deg)
        R = self.tilt @ self.leveling(level_fraction)
        return [
            (self.pivot + R @ arm, R @ rotation)
            for arm, rotation in zip(self._arms, self._rotations, strict=True)
        ]
