"""Every metric of an episode, defined once, from the env's per-step ``info`` (docs/metrics.md).

``EpisodeMetrics`` takes the reset's ``info`` and then, after every env step, that step's
``info``, the observation, the action and the control time; ``result()`` gives the JSON-ready
metrics. It reads only the ``info`` keys that are present, so it works on every env (no tray:
the cup metrics are None) and on envs that report more (a free tray's ``tray_offset``).

Definitions (``dt`` the env step; "step" an env step after the reset):

* ``time_to_goal_s``: the earliest time from which the axle stays within 5 cm of the goal and
  slower than 5 cm/s to the episode's end (None if never, or after a fall).
* ``max_cup_friction_use``: the peak of ``info["cup_friction_use"]`` (tangential over ``mu``
  times normal force of the cup's contacts with the tray; 1 = slipping); ``cup_friction_use_p99``
  its 99th percentile over the steps; ``slipping_time_s``: ``dt`` times the number of steps with
  the use at or above ``SLIP_USE`` = 0.99 (a one-step touch of 1.0 counts 1 ms, a slide its
  whole length).
* ``cup_slip_distance_m``: path length of the cup's centre in the tray's frame, the sum over
  steps of ``|cup_offset[k] - cup_offset[k-1]|`` from the reset, up to and including the step
  the cup is lost (after that it is falling, not slipping).
* ``tray_slip_distance_m``: the same for ``info["tray_offset"]`` (the free tray's position in
  the hand's frame); 0 for a tray task whose env does not report it (a welded tray).
* ``max_cup_tilt_deg``: the peak angle between the cup's axis and the tray's normal, from
  ``info["cup_tilt_deg"]`` or, when absent, from the observation's ``cup_pose`` quaternion
  (``acos(1 - 2 (qx^2 + qy^2))``).
* ``cup_kept``: on every step the tray on the hand (``info["tray_on_hand"]``, True when not
  reported: welded) and the cup on it: ``cup_on_tray``, upright (``info["cup_upright"]`` or tilt
  at most ``UPRIGHT_DEG`` = 30 deg) and on the plate (``info["cup_on_plate"]`` when present). A
  cup that rides a dropped tray is not kept. ``cup_lost_at_s``: the first step it is not.
* ``tray_kept``: ``info["tray_on_hand"]`` on every step (True when not reported: welded).
* ``outcome``: the episode's one outcome. In a tray task ``"carried"`` (on every step the robot
  up, the tray on the hand and the cup on the plate, upright) or its first loss: ``"fell"``,
  ``"tray_lost"``, ``"cup_lost"``; without a tray ``"balanced"`` (never fell) or ``"fell"``.
  When losses first appear on the same step the cause is named: ``fell`` before ``tray_lost``
  before ``cup_lost`` (``LOSS_ORDER``). ``outcome_time_s``: the time of that step (None when
  carried or balanced). Only the first loss counts, so the outcome is the same whether the env
  ends the episode at the loss or runs on (``terminate_on_cup_loss``).
* ``carried``: ``outcome == "carried"``; None without a tray (so its rate is null, not 0).
* ``success``: reached the goal and carried (without a tray: reached the goal, not fallen).
* ``time_at_actuator_limit_s``: ``dt`` times the steps on which some torque is at its bound
  (within ``LIMIT_RTOL`` of it).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

GOAL_TOLERANCE_M = 0.05
STOP_SPEED_M_S = 0.05
SLIP_USE = 0.99
UPRIGHT_DEG = 30.0
LIMIT_RTOL = 1e-6
#: the losses in the order they are named when several first appear on the same step: the cause
#: first (a fall drops the tray, a dropped tray takes the cup)
LOSS_ORDER = ("fell", "tray_lost", "cup_lost")
CARRIED = "carried"
BALANCED = "balanced"  # the outcome of an episode without a tray that did not fall
OUTCOMES = (CARRIED, BALANCED, *LOSS_ORDER)


def time_to_goal(t: np.ndarray, distance: np.ndarray, speed: np.ndarray) -> float | None:
    """The earliest time from which the robot stays within 5 cm of the goal and slower than
    5 cm/s until the episode's end; None if it never does."""
    ok = (distance < GOAL_TOLERANCE_M) & (speed < STOP_SPEED_M_S)
    if len(ok) == 0 or not ok[-1]:
        return None
    failures = np.flatnonzero(~ok)
    first = 0 if len(failures) == 0 else failures[-1] + 1
    return float(t[first])


def step_loss(fallen: bool, tray_on_hand: bool = True, cup_on_tray: bool = True) -> str | None:
    """The loss one step shows, named by :data:`LOSS_ORDER` when it shows several (the cause
    first); None when the robot is up, the tray on the hand and the cup on the plate."""
    if fallen:
        return "fell"
    if not tray_on_hand:
        return "tray_lost"
    if not cup_on_tray:
        return "cup_lost"
    return None


def outcome_counts(episodes: Sequence[Mapping[str, Any]]) -> dict[str, int]:
    """Episodes per ``outcome``, for the outcomes that occur, in the order of :data:`OUTCOMES`
    (an episode without one, recorded before outcomes existed, is not counted)."""
    counts = {kind: sum(1 for e in episodes if e.get("outcome") == kind) for kind in OUTCOMES}
    return {kind: n for kind, n in counts.items() if n}


def path_length(points: NDArray[np.float64]) -> float:
    """Sum of the distances between consecutive rows of ``points`` (k, d)."""
    if len(points) < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def tilt_from_quaternion(quat: NDArray[np.float64]) -> float:
    """Angle (deg) between the z axes of two frames related by the unit quaternion
    ``(w, x, y, z)``: ``acos(1 - 2 (x^2 + y^2))``."""
    w, x, y, z = (float(v) for v in quat)
    norm2 = w * w + x * x + y * y + z * z
    cosine = 1.0 - 2.0 * (x * x + y * y) / norm2
    return math.degrees(math.acos(min(1.0, max(-1.0, cosine))))


class EpisodeMetrics:
    """Accumulates one episode's per-step signals; ``result()`` computes every metric."""

    def __init__(
        self,
        dt: float,
        reset_info: Mapping[str, Any],
        reset_observation: Mapping[str, Any] | None = None,
        action_low: NDArray[np.float64] | None = None,
        action_high: NDArray[np.float64] | None = None,
    ) -> None:
        self.dt = float(dt)
        self.has_cup = "cup_on_tray" in reset_info
        self.has_ee = "ee_error" in reset_info
        self._low = None if action_low is None else np.asarray(action_low, dtype=float)
        self._high = None if action_high is None else np.asarray(action_high, dtype=float)
        # the bands within LIMIT_RTOL of each bound, made once (update tests every step's action)
        self._near_high: NDArray[np.float64] | None = None
        self._near_low: NDArray[np.float64] | None = None
        if self._low is not None and self._high is not None:
            tolerance = LIMIT_RTOL * np.maximum(1.0, np.abs(self._high - self._low))
            self._near_high, self._near_low = self._high - tolerance, self._low + tolerance
        self._distance: list[float] = []
        self._speed: list[float] = []
        self._fallen = False
        self._ee: list[float] = []
        self._tilt: list[float] = []
        self._friction: list[float] = []
        self._cup_tilt: list[float] = []
        self._cup_offset: list[NDArray[np.float64]] = []
        self._tray_offset: list[NDArray[np.float64]] = []
        self._kept: list[bool] = []
        self._tray_kept: list[bool] = []
        self._at_limit = 0
        self._control_times: list[float] = []
        self._loss: str | None = None  # the first loss and the step (1-based) it appeared on
        self._loss_step = 0
        if self.has_cup:
            self._tilt.append(float(reset_info["tray_tilt_deg"]))
            self._cup_offset.append(np.array(reset_info["cup_offset"], dtype=float))
            if "tray_offset" in reset_info:
                self._tray_offset.append(np.array(reset_info["tray_offset"], dtype=float))
            tilt = self._cup_tilt_of(reset_info, reset_observation)
            if tilt is not None:
                self._cup_tilt.append(tilt)

    @staticmethod
    def _cup_tilt_of(
        info: Mapping[str, Any], observation: Mapping[str, Any] | None
    ) -> float | None:
        if "cup_tilt_deg" in info:
            return float(info["cup_tilt_deg"])
        if observation is not None and "cup_pose" in observation:
            return tilt_from_quaternion(np.asarray(observation["cup_pose"])[3:7])
        return None

    def update(
        self,
        info: Mapping[str, Any],
        observation: Mapping[str, Any] | None = None,
        action: NDArray[np.float64] | None = None,
        control_time_s: float | None = None,
    ) -> None:
        """One env step's ``info`` (and the observation it returned, the action that made it,
        the controller's compute time for that action)."""
        self._distance.append(float(info["goal_distance"]))
        self._speed.append(abs(float(info["xd"])))
        fallen = bool(info["fallen"])
        self._fallen = self._fallen or fallen
        if self.has_ee:
            self._ee.append(float(info["ee_error"]))
        on_hand, on_tray = True, True
        if self.has_cup:
            self._tilt.append(float(info["tray_tilt_deg"]))
            self._friction.append(float(info["cup_friction_use"]))
            self._cup_offset.append(np.array(info["cup_offset"], dtype=float))
            if "tray_offset" in info:
                self._tray_offset.append(np.array(info["tray_offset"], dtype=float))
            tilt = self._cup_tilt_of(info, observation)
            if tilt is not None:
                self._cup_tilt.append(tilt)
            upright = info.get("cup_upright")
            if upright is None:
                upright = tilt is None or tilt <= UPRIGHT_DEG
            on_tray = bool(info["cup_on_tray"]) and bool(upright)
            on_tray = on_tray and bool(info.get("cup_on_plate", True))
            on_hand = bool(info.get("tray_on_hand", True))
            self._kept.append(on_tray and on_hand)  # a cup on a dropped tray is not kept
            self._tray_kept.append(on_hand)
        if self._loss is None:
            self._loss = step_loss(fallen, on_hand, on_tray)
            self._loss_step = len(self._distance)
        if action is not None and self._near_high is not None and self._near_low is not None:
            a = np.asarray(action, dtype=float)
            at_limit = (a >= self._near_high) | (a <= self._near_low)
            self._at_limit += int(bool(at_limit.any()))
        if control_time_s is not None:
            self._control_times.append(float(control_time_s))

    @property
    def steps(self) -> int:
        return len(self._distance)

    @property
    def control_times(self) -> NDArray[np.float64]:
        return np.array(self._control_times)

    def result(self) -> dict[str, Any]:
        """Every metric (JSON-ready); the cup's are None without a cup, ``max_ee_error_m``
        None without an end-effector."""
        n, dt = self.steps, self.dt
        if n == 0:
            raise ValueError("no env step recorded: an episode needs at least one step")
        times = np.arange(1, n + 1) * dt
        distance, speed = np.array(self._distance), np.array(self._speed)
        fell = self._fallen
        reached_at = None if fell else time_to_goal(times, distance, speed)
        metrics: dict[str, Any] = {
            "steps": n,
            "sim_time_s": n * dt,
            "fell": bool(fell),
            "goal_reached": reached_at is not None,
            "time_to_goal_s": reached_at,
            "final_goal_error_m": float(distance[-1]),
            "max_ee_error_m": max(self._ee) if self.has_ee else None,
            "time_at_actuator_limit_s": self._at_limit * dt if self._low is not None else None,
        }
        metrics.update(self._cup_metrics())
        metrics.update(self._outcome())
        carried = metrics["carried"]
        metrics["success"] = bool(
            metrics["goal_reached"] and not fell and (carried is None or carried)
        )
        return metrics

    def _outcome(self) -> dict[str, Any]:
        """``outcome``, ``outcome_time_s`` and ``carried`` (docs/metrics.md §1)."""
        if self._loss is not None:
            outcome, time = self._loss, self._loss_step * self.dt
        else:
            outcome, time = (CARRIED if self.has_cup else BALANCED), None
        return {
            "outcome": outcome,
            "outcome_time_s": time,
            "carried": (outcome == CARRIED) if self.has_cup else None,
        }

    def _cup_metrics(self) -> dict[str, Any]:
        keys = (
            "cup_kept",
            "cup_lost_at_s",
            "tray_kept",
            "max_tray_tilt_deg",
            "max_cup_friction_use",
            "cup_friction_use_p99",
            "slipping_time_s",
            "cup_slip_distance_m",
            "tray_slip_distance_m",
            "max_cup_tilt_deg",
        )
        if not self.has_cup:
            return dict.fromkeys(keys)
        dt = self.dt
        kept = np.array(self._kept)
        lost = np.flatnonzero(~kept)
        # offsets[0] is the reset's; offsets[k] follows step k (1-based), so the path up to
        # and including the step the cup is lost ends at offsets[lost + 1]
        end = len(self._cup_offset) if len(lost) == 0 else int(lost[0]) + 2
        friction = np.array(self._friction)
        tray_end = len(self._tray_offset) if len(lost) == 0 else min(end, len(self._tray_offset))
        return {
            "cup_kept": bool(kept.all()),
            "cup_lost_at_s": None if len(lost) == 0 else float((lost[0] + 1) * dt),
            "tray_kept": bool(all(self._tray_kept)),
            "max_tray_tilt_deg": float(max(self._tilt)),
            "max_cup_friction_use": float(friction.max()),
            "cup_friction_use_p99": float(np.percentile(friction, 99)),
            "slipping_time_s": float(np.count_nonzero(friction >= SLIP_USE) * dt),
            "cup_slip_distance_m": path_length(np.array(self._cup_offset[:end])),
            "tray_slip_distance_m": path_length(np.array(self._tray_offset[:tray_end]))
            if self._tray_offset
            else 0.0,
            "max_cup_tilt_deg": float(max(self._cup_tilt)) if self._cup_tilt else None,
        }
