"""The offline plan: DDP on the WIPM over the whole horizon (paper section "Receding Horizon
Control").

From the current state and ``lambda(q)`` to the goal over ``t_f`` (20 s at 10 ms: 2000 steps),
weights as the paper describes (a high weight on ``theta`` for heavy robots, terminal weights)
plus a penalty on the control's rate of change (the authors' later code), and penalties that
keep the axle's horizontal acceleration under ``a_max`` and ``|theta|`` under ``theta_max``.
Every plan is checked against those bounds and against arrival (within 1 cm of the goal with
speeds near zero by ``0.6 t_f``); a violation is reported in ``Plan.violations``.

A finite-horizon plan ends where its terminal cost left it, not always at the goal (on a
short or aggressive drive it ends leaning and still braking). Past ``t_f`` the plan is continued
by a stiff LQR of its own problem linearised at the goal, its control's rate bounded by a
multiple of the plan's own largest, rolled out on the WIPM from the plan's last state and
control until it rests at the goal (``controllers.high_level.settling``); past that the
reference holds :attr:`Plan.rest_state`.
The reference every controller reads (:meth:`Plan.state`, :meth:`Plan.window`,
:meth:`Plan.sample`, the MPC's window) has no step at ``t_f`` (a step there is answered by the
MPC with a jolt; docs/controllers.md §3.1).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Literal

import jax
import numpy as np

from controllers.high_level.settling import Envelope, Settling, settle
from controllers.optimizer import jax_setup
from controllers.optimizer.ddp import DDPConfig
from controllers.simplified.wipm import WIPMParams
from controllers.simplified.wipm_problem import (
    PLANAR_STATE,
    SPATIAL_STATE,
    Weights,
    WIPMProblem,
    ddp_solver_for,
    refs_for,
)
from wip_gym.scene import GRAVITY

A_MAX_SPELLINGS = ("cup_safe", "none")
#: a plan has arrived within 1 cm of the goal (m), slower than 1 cm/s and 0.01 rad/s
ARRIVAL_DISTANCE = 0.01
ARRIVAL_SPEED = 0.01


@dataclass(frozen=True)
class PlanConfig:
    """Offline plan settings. Authors' values (docs/AUTHORS_CONFIG.md §3.2) for comparison.

    Attributes:
        horizon_s, dt: ``t_f`` and the step: 20 s at 10 ms (authors: the same).
        a_max: how aggressive the plan may be, independent of the cup's friction when given as
            a number: ``"cup_safe"`` (default) caps the axle's horizontal acceleration at
            ``0.5 mu g`` in tray tasks (``mu`` the scenario's cup friction: a level tray then
            uses half its friction, by construction) and at ``default_a_max`` without a cup;
            ``"none"``: no cap (the authors' plan, docs/AUTHORS_CONFIG.md §3.2); a float: that
            cap in m/s^2. ``None`` is the older spelling of ``"cup_safe"``.
        default_a_max: the ``"cup_safe"`` bound without a cup (1 m/s^2: a gentle drive for a
            160 kg robot).
        theta_max: bound on ``|theta|`` (rad); 0.25 rad (14 deg).
        arrival_fraction: the plan must arrive by this fraction of ``t_f`` (0.6).
        q_theta, q_thetad, q_position, q_speed: running weights on the WIPM state (the paper:
            higher on positions and ``theta`` than on speeds; authors' 3-D Q = [0, 0.1, 1.0,
            0.1, 0.1, 0.1, 0.1, 0.1] over [x, psi, theta, xd, psid, thetad, X0, Y0]).
        q_heading: running weight on ``psi`` (3-D): toward the given final heading, or, with
            the heading free, toward the bearing of the goal from the start (so the plan turns
            to face the goal and drives forward rather than spinning or reversing); the
            terminal weight on ``psi`` is zero when the heading is free.
        r_control: weights on ``[thdd, tau_0]`` (authors R = 0.01, 0.01).
        r_rate: weights on the control's rate (authors 0.01, 0.01 on u-dot). We use 1.0: a
            smoother ``thdd`` gives a smoother axle acceleration, which a cup (and the waiter's
            tray, which must tilt as fast as the acceleration changes) can follow; with 0.01 the
            acceleration flips sign within ~0.1 s mid-drive.
        r_rate_spin: weight on ``tau_0``'s rate (3-D; the authors' 0.01: ``tau_0`` is in N m).
        q_terminal: terminal weight on every tracked state (authors 1e4).
        settle_tolerance: the continuation past ``t_f`` (module docstring) ends at the first
            step where every coordinate it steers is within this of the goal (SI units: m, rad,
            m/s, rad/s, rad/s^2, N m); 1e-9, far below anything a controller responds to.
        settle_max_s: the longest continuation (s); one that has not settled by then is kept
            and reported in ``Plan.violations``. 120 s: the longest measured, KrangTray-v0
            under the paper's weights (the spin settles with a time constant of 4.4 s), takes
            53 s (docs/controllers.md §3.1).
        settle_stiffness: the stiffest rung of the continuation's feedback: its LQR weighs the
            plan's running weights on the state and the control this many times against those
            on the control's rate (``controllers.high_level.settling``). 1000: its slowest time
            constant, 0.546 s on PlanarTray-v0, is within 1 % of the floor that stiffer weights
            reach (0.545 s); the plan's own weights (1) give 1.43 s.
        settle_rate_factor: the continuation's control rate is bounded by this times the plan's
            own largest. 1.8: on the aggressive drive of docs/controllers.md §3.1 the reference
            is within the benchmark's goal criterion (5 cm, 5 cm/s) from 3.71 s against 4.65 s
            at 1 (the plan's own largest rate), and its second differences stay within 1.84
            times the plan's largest, below the 2 at which ``tests/test_plan_end.py`` calls a
            step; 2 goes beyond that (2.03) for no earlier arrival (3.70 s).
        ddp: solver settings (authors: 50 iterations, iLQR; no gradient norm: the plan stops on
            the predicted decrease).
    """

    horizon_s: float = 20.0
    dt: float = 0.01
    a_max: float | Literal["cup_safe", "none"] | None = "cup_safe"
    default_a_max: float = 1.0
    theta_max: float = 0.25
    arrival_fraction: float = 0.6
    q_theta: float = 10.0
    q_thetad: float = 0.1
    q_position: float = 10.0
    q_speed: float = 0.1
    q_heading: float = 5.0
    r_control: float = 0.01
    r_rate: float = 1.0
    r_rate_spin: float = 0.01
    q_terminal: float = 1e4
    settle_tolerance: float = 1e-9
    settle_max_s: float = 120.0
    settle_stiffness: float = 1000.0
    settle_rate_factor: float = 1.8
    ddp: DDPConfig = field(
        default_factory=lambda: DDPConfig(
            max_iterations=100, tolerance=1e-9, second_order=False, gradient_norm=False
        )
    )

    def __post_init__(self) -> None:
        a_max = self.a_max
        if isinstance(a_max, str):
            if a_max not in A_MAX_SPELLINGS:
                raise ValueError(
                    f"a_max must be a positive number (m/s^2) or one of "
                    f"{A_MAX_SPELLINGS}, got {a_max!r}"
                )
        elif a_max is not None and (
            isinstance(a_max, bool)
            or not isinstance(a_max, int | float)
            or not np.isfinite(a_max)
            or a_max <= 0
        ):
            raise ValueError(
                f"a_max must be a positive number (m/s^2) or one of "
                f"{A_MAX_SPELLINGS}, got {a_max!r}"
            )
        if not (np.isfinite(self.default_a_max) and self.default_a_max > 0):
            raise ValueError(f"default_a_max must be positive, got {self.default_a_max!r}")
        for name in ("settle_tolerance", "settle_max_s", "settle_stiffness", "settle_rate_factor"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be positive, got {value!r}")

    @classmethod
    def paper(cls) -> PlanConfig:
        """The authors' offline DDP (docs/AUTHORS_CONFIG.md §3.2): running weights [0, 0.1,
        1.0, 0.1, 0.1, 0.1, 0.1, 0.1] over [x, psi, theta, xd, psid, thetad, X0, Y0] (planar:
        theta 1.0, thetad 0.1, x 0.1, xd 0.1), R = 0.01, control-rate weights 0.01, terminal
        1e4, 20 s at 10 ms, and no acceleration cap. Kept from ours: the DDP solver settings,
        the ``theta_max`` check and the arrival check (both only report)."""
        return cls(
            a_max="none",
            q_theta=1.0,
            q_thetad=0.1,
            q_position=0.1,
            q_speed=0.1,
            q_heading=0.1,
            r_control=0.01,
            r_rate=0.01,
            r_rate_spin=0.01,
            q_terminal=1e4,
        )

    @property
    def steps(self) -> int:
        steps = self.horizon_s / self.dt
        if abs(steps - round(steps)) > 1e-9:
            raise ValueError(f"horizon {self.horizon_s} s is not a whole number of {self.dt} s")
        return int(round(steps))

    def acceleration_bound(self, cup_friction: float | None, gravity: float = GRAVITY) -> float:
        """The cap on the axle's horizontal acceleration (m/s^2; ``inf`` for ``"none"``)."""
        if self.a_max == "none":
            return float("inf")
        if self.a_max is None or self.a_max == "cup_safe":
            if cup_friction is None:
                return self.default_a_max
            return 0.5 * cup_friction * gravity
        return float(self.a_max)


@dataclass(frozen=True)
class Plan:
    """An offline plan of the WIPM, continued past its end until it rests at the goal (module
    docstring).

    Attributes:
        times: (N+1,) s. states: (N+1, n) WIPM states. controls: (N, m) ``thdd`` (``tau_0``).
        goal_state: the target state (3-D: with the ``x`` the plan rests at, ``x`` being no
            part of the goal). planar: model variant.
        settle_states: (K, n) the states after ``t_f`` (at ``t_f + dt`` to ``t_f + K dt``) of
            the continuation (:func:`settle`); K = 0 when the plan ends at the goal.
        settle_controls: (K, m) its controls, from the one at ``t_f`` (the plan's last control
            continued: the control is part of the DDP's state, so it does not jump).
        rest_state: the state the reference holds after the continuation: ``goal_state``,
            except in 3-D when the continuation ends beside the goal by less than
            :data:`ARRIVAL_DISTANCE`: then ``(X0, Y0)`` is the goal moved sideways by that
            offset, which the continuation cannot roll away, and, when the heading is free,
            ``psi`` is where the continuation left it (it does not steer a free heading;
            ``controllers.high_level.settling``), so that the reference has no step there
            either. Further aside the plan did not arrive: the rest state is the goal, and the
            step to it is reported in ``violations``.
        cost, iterations, converged: from the DDP.
        peak_acceleration, peak_theta: measured on the plan (to ``t_f``).
        arrival_time: first time from which the plan stays within 1 cm of the goal with speeds
            under 1 cm/s (and 0.01 rad/s), None if never.
        a_max, theta_max: the bounds it was planned under. violations: human-readable list
            (the continuation's too).
    """

    times: np.ndarray
    states: np.ndarray
    controls: np.ndarray
    goal_state: np.ndarray
    planar: bool
    cost: float
    iterations: int
    converged: bool
    peak_acceleration: float
    peak_theta: float
    arrival_time: float | None
    a_max: float
    theta_max: float
    violations: tuple[str, ...]
    settle_states: np.ndarray
    settle_controls: np.ndarray
    rest_state: np.ndarray

    @property
    def dt(self) -> float:
        return float(self.times[1] - self.times[0])

    @functools.cached_property
    def reference_states(self) -> np.ndarray:
        """(N+1+K, n): the plan's states, then its continuation's (read-only)."""
        return _frozen(np.vstack([self.states, self.settle_states]))

    @functools.cached_property
    def reference_controls(self) -> np.ndarray:
        """(N+K, m): the plan's controls, then its continuation's (read-only)."""
        return _frozen(np.vstack([self.controls, self.settle_controls]))

    @functools.cached_property
    def reference_times(self) -> np.ndarray:
        """(N+1+K,) s: :attr:`times`, then the continuation's (read-only)."""
        extra = self.times[-1] + self.dt * np.arange(1, len(self.settle_states) + 1)
        return _frozen(np.concatenate([self.times, extra]))

    def state(self, index: int) -> np.ndarray:
        """The reference at index ``index``: the plan's state, its continuation's past ``t_f``,
        the rest state past that (``window(index, 1)[0]`` without building the window: the
        controllers record it every control step)."""
        states = self.reference_states
        return states[index] if index < len(states) else self.rest_state

    def states_at(self, indices: np.ndarray) -> np.ndarray:
        """:meth:`state` of each of ``indices`` (integers >= 0), as rows."""
        states = self.reference_states
        padded = np.vstack([states, self.rest_state[None, :]])
        return padded[np.minimum(np.asarray(indices, dtype=np.intp), len(states))]

    def window(self, start: int, count: int) -> np.ndarray:
        """``count`` states of the reference (:meth:`state`) from index ``start``."""
        out = np.tile(self.rest_state, (count, 1))
        available = self.reference_states[start : start + count]
        out[: len(available)] = available
        return out

    @functools.cached_property
    def _state_rows(self) -> np.ndarray | None:
        """The reference's states by quantity, each row contiguous (:meth:`sample` reads them
        every control step; ``np.interp`` of a column of ``states`` copied it first); None for a
        plan with a non-finite state, which :meth:`sample` reads through ``np.interp`` itself
        (whose special cases for NaN and inf the shortcut does not repeat). ``plan_to_goal``
        makes a plan's arrays read-only, so the rows cannot go stale."""
        states = self.reference_states
        if not np.isfinite(states).all():
            return None
        return np.ascontiguousarray(states.T)

    def sample(self, t: float) -> dict[str, float]:
        """The reference at time ``t`` (linear interpolation of the plan and its continuation;
        the rest state after them, the first state before the start), by name: ``theta,
        thetad, x, xd`` (3-D also ``psi, psid, X0, Y0``). ``np.interp``'s arithmetic for all
        quantities at once: the same floats (tested), a fifth of the time of one ``np.interp``
        per quantity."""
        times = self.reference_times
        if t != t:
            raise ValueError("plan time t is NaN")
        rows = self._state_rows
        if t >= times[-1]:
            state = self.rest_state
        elif rows is None:
            state = np.array([np.interp(t, times, column) for column in self.reference_states.T])
        elif t < times[0]:
            state = self.reference_states[0]
        else:
            j = int(np.searchsorted(times, t, side="right")) - 1
            low, high = rows[:, j], rows[:, j + 1]
            state = (high - low) / (times[j + 1] - times[j]) * (t - times[j]) + low
        names = PLANAR_STATE if self.planar else SPATIAL_STATE
        return dict(zip(names, state.tolist(), strict=True))

    def control_window(self, start: int, count: int) -> np.ndarray:
        """``count`` controls of the reference from index ``start``, zeros past it."""
        out = np.zeros((count, self.controls.shape[1]))
        available = self.reference_controls[start : start + count]
        out[: len(available)] = available
        return out


def _frozen(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


def planning_problem(
    planar: bool, config: PlanConfig, a_max: float, heading_given: bool
) -> WIPMProblem:
    c = config
    # state and control sizes differ: planar 4 and 1, spatial 8 and 2
    q: tuple[float, ...]
    q_terminal: tuple[float, ...]
    r: tuple[float, ...]
    r_rate: tuple[float, ...]
    if planar:
        q = (c.q_theta, c.q_thetad, c.q_position, c.q_speed)
        q_terminal = (c.q_terminal,) * 4
        r = (c.r_control,)
        r_rate = (c.r_rate,)
    else:
        # x (odometry) is not tracked: the position is (X0, Y0)
        q = (
            0.0,
            c.q_heading,
            c.q_theta,
            c.q_speed,
            c.q_speed,
            c.q_thetad,
            c.q_position,
            c.q_position,
        )
        q_terminal = (0.0, c.q_terminal if heading_given else 0.0, *(c.q_terminal,) * 6)
        r = (c.r_control, c.r_control)
        r_rate = (c.r_rate, c.r_rate_spin)
    weights = Weights(
        q=q, r=r, r_rate=r_rate, q_terminal=q_terminal, a_max=a_max, theta_max=c.theta_max
    )
    return WIPMProblem(planar=planar, dt=c.dt, weights=weights)


@functools.lru_cache(maxsize=16)
def _accelerations(problem: WIPMProblem):  # noqa: ANN202 (a jitted function)
    return jax.jit(jax.vmap(problem.horizontal_acceleration, in_axes=(0, 0, None)))


def arrival_time(
    times: np.ndarray, states: np.ndarray, goal: np.ndarray, planar: bool
) -> float | None:
    """First time from which the plan stays within :data:`ARRIVAL_DISTANCE` of the goal,
    slower than :data:`ARRIVAL_SPEED`."""
    if planar:
        distance = np.abs(states[:, 2] - goal[2])
        speeds = np.abs(states[:, [1, 3]]).max(axis=1)
    else:
        distance = np.hypot(states[:, 6] - goal[6], states[:, 7] - goal[7])
        speeds = np.abs(states[:, [3, 4, 5]]).max(axis=1)
    ok = (distance < ARRIVAL_DISTANCE) & (speeds < ARRIVAL_SPEED)
    if not ok[-1]:
        return None
    bad = np.flatnonzero(~ok)
    return float(times[0 if len(bad) == 0 else bad[-1] + 1])


def plan_to_goal(
    state: np.ndarray,
    params: WIPMParams,
    goal_xy: np.ndarray,
    *,
    planar: bool,
    cup_friction: float | None = None,
    goal_heading: float | None = None,
    config: PlanConfig | None = None,
) -> Plan:
    """DDP from ``state`` (a WIPM state) to the goal (planar: ``x = goal_xy[0]``; 3-D:
    ``(X0, Y0) = goal_xy``, heading free unless ``goal_heading``), at rest and upright."""
    config = config or PlanConfig()
    state = np.asarray(state, dtype=float)
    n = 4 if planar else 8
    if state.shape != (n,) or not np.all(np.isfinite(state)):
        raise ValueError(f"state must be {n} finite numbers, got {state!r}")
    goal_xy = np.asarray(goal_xy, dtype=float)
    if goal_xy.shape != (2,) or not np.all(np.isfinite(goal_xy)):
        raise ValueError(f"goal must be a finite (x, y), got {goal_xy!r}")
    a_max = config.acceleration_bound(cup_friction, float(np.asarray(params.gravity)))
    problem = planning_problem(planar, config, a_max, goal_heading is not None)
    if planar:
        goal = np.array([0.0, 0.0, goal_xy[0], 0.0])
    else:
        if goal_heading is None:
            delta = goal_xy - state[6:8]
            bearing = np.arctan2(delta[1], delta[0]) if np.hypot(*delta) > 1e-6 else state[1]
            # the bearing closest to the current heading (no full turns)
            heading = state[1] + np.angle(np.exp(1j * (bearing - state[1])))
        else:
            heading = goal_heading
        goal = np.array([0.0, heading, 0.0, 0.0, 0.0, 0.0, *goal_xy])
    steps = config.steps
    m = problem.n_control
    z0 = np.concatenate([state, np.zeros(m)])
    refs = refs_for(np.tile(goal, (steps + 1, 1)), params)
    solver = ddp_solver_for(problem, config.ddp)
    result = solver(z0, np.zeros((steps, m)), params, refs)
    Z = np.asarray(result.X)
    states, controls = Z[:, :n], Z[:-1, n:]
    with jax_setup.float64():
        accelerations = np.asarray(_accelerations(problem)(states[:-1], controls, params))
    peak_a = float(accelerations.max())
    peak_theta = float(np.abs(states[:, problem.theta_index]).max())
    # the largest rate of each control (z0's control is zero: the plan's first rate counts)
    peak_rate = np.abs(np.diff(Z[:, n:], axis=0)).max(axis=0) / config.dt
    times = np.arange(steps + 1) * config.dt
    # past t_f: the plan continued until it rests at the goal (controllers.high_level.settling)
    settle_steps = int(np.ceil(config.settle_max_s / config.dt - 1e-9))
    if not np.all(np.isfinite(Z)):
        settling = Settling(np.zeros((0, n)), np.zeros((0, m)), np.zeros(0), False)
    else:
        with jax_setup.float64():
            settling = settle(
                problem,
                Z[-1],
                np.concatenate([goal, np.zeros(m)]),
                params,
                config.settle_tolerance,
                settle_steps,
                Envelope(config.settle_rate_factor * peak_rate, peak_a, peak_theta),
                config.settle_stiffness,
                heading_free=goal_heading is None,
            )
    last = settling.states[-1] if len(settling.states) else states[-1]
    rest = goal.copy()
    sideways_step = 0.0
    if not planar:
        # x (the distance rolled) is no part of the 3-D goal (its weight is 0: the goal is
        # (X0, Y0)), so past the end the plan holds the x it rests at, not 0: a controller
        # that tracks x from the plan (the decoupled baselines) must see no step; the rest
        # state keeps a free heading where the plan left it, and the sideways offset from the
        # goal the plan arrived with, which rolling cannot remove
        # (controllers.high_level.settling)
        goal = goal.copy()
        goal[0] = rest[0] = last[0]
        across = np.array([-np.sin(goal[1]), np.cos(goal[1])])
        aside = float(across @ (last[6:8] - goal[6:8]))
        if abs(aside) < ARRIVAL_DISTANCE:
            rest[6:8] = goal[6:8] + aside * across
            if goal_heading is None:
                rest[1] = last[1]
        else:  # not arrived: the reference still leads to the goal, with a step
            sideways_step = aside
    arrival = arrival_time(times, states, goal, planar)
    violations = []
    if peak_a > a_max:
        violations.append(f"peak acceleration {peak_a:.3f} m/s^2 > a_max {a_max:.3f}")
    if peak_theta > config.theta_max:
        violations.append(f"peak |theta| {peak_theta:.3f} rad > theta_max {config.theta_max}")
    deadline = config.arrival_fraction * config.horizon_s
    if arrival is None or arrival > deadline:
        violations.append(f"arrives at {arrival} s, after {deadline:.1f} s")
    if not np.all(np.isfinite(Z)):
        violations.append("non-finite plan")
    if settling.failure is not None:
        violations.append(f"the continuation past t_f: {settling.failure}")
    if sideways_step:
        violations.append(
            f"the continuation past t_f ends {abs(sideways_step):.3f} m beside the goal: the "
            "reference steps to it there"
        )
    if len(settling.states):
        settle_a = float(settling.accelerations.max())
        settle_theta = float(np.abs(settling.states[:, problem.theta_index]).max())
        if settle_a > a_max:
            violations.append(
                f"the continuation past t_f: peak acceleration {settle_a:.3f} m/s^2 > a_max "
                f"{a_max:.3f}"
            )
        if settle_theta > config.theta_max:
            violations.append(
                f"the continuation past t_f: peak |theta| {settle_theta:.3f} rad > theta_max "
                f"{config.theta_max}"
            )
    settle_states, settle_controls = settling.states, settling.controls
    for array in (times, states, controls, goal, settle_states, settle_controls, rest):
        array.flags.writeable = False  # a Plan is frozen (Plan.sample keeps its states' rows)
    return Plan(
        times=times,
        states=states,
        controls=controls,
        goal_state=goal,
        planar=planar,
        cost=float(result.cost),
        iterations=int(result.iterations),
        converged=bool(result.converged),
        peak_acceleration=peak_a,
        peak_theta=peak_theta,
        arrival_time=arrival,
        a_max=a_max,
        theta_max=config.theta_max,
        violations=tuple(violations),
        settle_states=settle_states,
        settle_controls=settle_controls,
        rest_state=rest,
    )
