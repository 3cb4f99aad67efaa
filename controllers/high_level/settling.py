"""The offline plan's continuation past its end (docs/controllers.md §3.1).

A plan over a finite horizon ends where its terminal cost left it, which on a short or
aggressive drive is not the goal: on PlanarTray-v0 with ``goal = 1``, ``horizon_s = 3`` and no
acceleration cap it ends 12.7 mrad back, 2.7 mm short and still braking at ``thdd = -1.24``
rad/s^2. A reference that steps from there to the goal at ``t_f`` is answered by the MPC with
a jolt (its ``thdd`` doubled to -7 rad/s^2 there, the axle's acceleration 4.5 m/s^2 for
~50 ms).

:func:`settle` continues the plan from its last DDP state ``z_N = [s_N, u_N]`` (the control
is part of the plan's state, so it does not jump) under a constant feedback on the control's
rate, bounded per control,

    w = clip(-G (z - z_goal), -w_max, w_max),

rolled out on the plan's own discrete dynamics (the nonlinear WIPM, explicit Euler, the plan's
``lambda(q)``) until every coordinate it steers is within a tolerance of the goal.

* ``G`` (:func:`settling_gain`) is the infinite-horizon LQR of the plan's problem linearised at
  the goal at rest, its running weights on the state and the control (the shape of the plan's
  and the MPC's tracking cost) scaled by a stiffness against its weights on the control's rate.
  As the stiffness grows the unbounded loop's slowest time constant
  (:func:`slowest_time_constant`) falls to a floor that the weights' shape sets: on
  PlanarTray-v0 1.43 s at stiffness 1 (the plan's own weights), 0.96 s at 10, 0.61 s at 100,
  0.546 s at 1000 (``PlanConfig.settle_stiffness``), 0.545 s at 1e4 and 1e6; on KrangTray-v0
  with a given heading 1.21 s at 1000 (the spin, ``psi`` and ``psid``; 1.66 s at 1) under
  ``PlanConfig()``, 3.05 s (3.19 s at 1) under ``PlanConfig.paper()``, and with a free heading
  4.5 s at any stiffness under either (``psid`` and ``tau_0``: their weights' ratio sets it, as
  the spin's inertia does).
* ``w_max`` is ``PlanConfig.settle_rate_factor`` (1.8) times the plan's own largest rate of
  each control: the continuation bends ``thdd`` at most 1.8 times as fast as the plan did, so
  on the aggressive drive the reference's second differences stay within 1.84 times the
  plan's largest (``thetad`` 1.8, ``xd`` 1.84; a step, in ``tests/test_plan_end.py``, is a
  second difference beyond twice the plan's).

A stiff gain under a bounded rate is a saturated linear feedback of a chain of integrators
(``w`` integrates to ``thdd``, to ``thetad``, to ``theta``, which drives ``xd`` and ``x``):
not stable from every state, and the stiffer the gain the smaller the region it settles from.
So the gain is taken from a ladder of stiffnesses, from ``settle_stiffness`` down by decades
to 1: the first whose bounded rollout settles, without going beyond the plan's own peaks of
acceleration and ``|theta|``, is the continuation. A softer gain saturates less, and one soft
enough does not saturate at all (``G`` goes to zero with the stiffness: the open loop is a chain
of integrators), where the LQR settles from anywhere the linearisation holds. If no rung
passes, the rung that settles going least beyond the peaks is kept (a state the plan left
leaning and turning fast may need more lean than the plan's to stop), else the softest rung's
rollout, and the failure is reported (``Plan.violations``).

On the aggressive drive above the first rung passes: the rate is held at its bound (16.1
rad/s^3) for the first 0.05 s while ``thdd`` turns round, and the continuation swings back to
3.6 cm behind the goal and is within 1 cm and 1 cm/s of it 1.99 s after ``t_f``. Bounded by
the plan's own largest rate (``settle_rate_factor = 1``, 8.9 rad/s^3) it is held there 0.21
s, swings back 5.7 cm and is within 1 cm and 1 cm/s 2.23 s after ``t_f``, where the least any
continuation within that envelope can do is 4.1 cm and 1.24 s (the plan's model linearised at
the goal, a linear programme over the rate profile with the plan's peaks of acceleration and
``|theta|`` as bounds; to rest exactly it needs 1.73 s). ``tests/test_plan_end.py`` holds
these; docs/controllers.md §3.1 has the closed loop's numbers.

The coordinates the feedback steers (:func:`steered_coordinates`): planar, all of ``[s, u]``;
3-D, all but ``x`` (the distance rolled: in neither the dynamics nor the cost), the sideways
offset from the goal, across the goal's heading, which the WIPM linearised at rest cannot
change (it cannot move sideways: that direction is uncontrollable), and, when the goal's
heading is free, ``psi`` (the plan has no terminal weight on it; its running weight toward the
goal's bearing only turns the drive to face the goal). ``Plan.rest_state`` keeps those where
the continuation ends.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg

from controllers.simplified.wipm import WIPMParams
from controllers.simplified.wipm_problem import WIPMProblem

#: rollout steps per compiled call: the continuation is rolled out in chunks of this many
#: steps until it settles (one compilation per problem, whatever its length)
CHUNK = 500


@dataclass(frozen=True)
class Envelope:
    """What the continuation may ask (module docstring): the plan's own peaks.

    Attributes:
        rate: (m,) the largest rate of each control (``w_max``: the feedback's bound).
        acceleration: the axle's largest horizontal acceleration (m/s^2).
        theta: the largest ``|theta|`` (rad).
    """

    rate: np.ndarray
    acceleration: float
    theta: float

    def __post_init__(self) -> None:
        rate = np.asarray(self.rate, dtype=float)
        if rate.ndim != 1 or not np.all(rate >= 0):
            raise ValueError(f"rate bounds must be a vector of numbers >= 0, got {self.rate!r}")
        for name in ("acceleration", "theta"):
            value = getattr(self, name)
            if not value >= 0:
                raise ValueError(f"the {name} bound must be a number >= 0, got {value!r}")


@dataclass(frozen=True)
class Settling:
    """A continuation of ``K`` steps past the plan's last state ``z_N``.

    Attributes:
        states: (K, n) the WIPM states at steps ``N+1 .. N+K``.
        controls: (K, m) the controls at steps ``N .. N+K-1`` (the first is ``z_N``'s).
        accelerations: (K,) the axle's horizontal acceleration at steps ``N .. N+K-1``.
        settled: whether it ended within the tolerance of the goal.
        stiffness: the rung of :func:`stiffness_ladder` it was rolled out with (0 when empty).
        failure: None when it settled within the envelope; else why not (then it is the
            stiffest rung's rollout that settled, beyond the envelope, or the softest rung's,
            stopped at the step budget; empty when not finite or without a gain).
    """

    states: np.ndarray
    controls: np.ndarray
    accelerations: np.ndarray
    settled: bool
    stiffness: float = 0.0
    failure: str | None = None


def steered_coordinates(problem: WIPMProblem, heading: float, heading_free: bool) -> np.ndarray:
    """Rows of an orthonormal map from the DDP's state ``z = [s, u]`` to the coordinates the
    feedback steers (module docstring): planar the identity; 3-D ``psi`` (unless
    ``heading_free``), ``theta, xd, psid, thetad, thdd, tau_0`` and the position along the
    goal's ``heading``."""
    n, m = problem.n_state, problem.n_control
    size = n + m
    if problem.planar:
        return np.eye(size)
    rows = np.eye(size)[[*([] if heading_free else [1]), 2, 3, 4, 5, n, n + 1]]
    along = np.zeros(size)
    along[6], along[7] = np.cos(heading), np.sin(heading)
    return np.vstack([rows, along])


def stiffness_ladder(stiffest: float) -> tuple[float, ...]:
    """``stiffest``, then down by decades to 1 (the plan's own weights), stiffest first; just
    ``stiffest`` when it is 1 or below."""
    if not (np.isfinite(stiffest) and stiffest > 0):
        raise ValueError(f"the settling stiffness must be positive, got {stiffest!r}")
    ladder = [float(stiffest)]
    while ladder[-1] / 10.0 >= 1.0 - 1e-12:
        ladder.append(ladder[-1] / 10.0)
    return tuple(ladder)


def settling_gain(
    problem: WIPMProblem,
    goal: np.ndarray,
    params: WIPMParams,
    steered: np.ndarray,
    stiffness: float,
) -> np.ndarray:
    """The gain ``G`` (``m`` x ``n + m``, zero on what is not steered) of the infinite-horizon
    LQR of the plan's problem linearised at ``goal`` (``z`` at rest, zero control and rate), in
    the steered coordinates: stage cost ``stiffness dt`` times the plan's running weights on
    the state and the control, plus ``dt`` times its weights on the control's rate
    (``problem.weights``; the penalties on acceleration and ``theta`` are zero at rest).
    ``ValueError`` when the gain does not stabilise the linearised model."""
    m = problem.n_control
    f_z, f_w = problem.dynamics_derivatives()(jnp.asarray(goal), jnp.zeros(m), params)
    A = steered @ np.asarray(f_z) @ steered.T
    B = steered @ np.asarray(f_w)
    weights, dt = problem.weights, problem.dt
    running = np.diag(np.concatenate([weights.q, weights.r]))
    Q = stiffness * dt * steered @ running @ steered.T
    R = dt * np.diag(np.asarray(weights.r_rate, dtype=float))
    P = scipy.linalg.solve_discrete_are(A, B, Q, R)
    gain = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
    radius = float(np.abs(np.linalg.eigvals(A - B @ gain)).max())
    if not radius < 1.0:
        raise ValueError(
            f"the LQR of stiffness {stiffness:g} at the goal does not settle (spectral radius "
            f"{radius:.6f})"
        )
    return np.asarray(gain @ steered)


def slowest_time_constant(
    problem: WIPMProblem,
    goal: np.ndarray,
    params: WIPMParams,
    steered: np.ndarray,
    stiffness: float,
) -> float:
    """The slowest time constant (s) of the linearised model at ``goal`` under the unbounded
    feedback of :func:`settling_gain`, in the steered coordinates: ``-dt / ln rho`` of the
    closed loop's spectral radius ``rho``."""
    gain = settling_gain(problem, goal, params, steered, stiffness)
    m = problem.n_control
    f_z, f_w = problem.dynamics_derivatives()(jnp.asarray(goal), jnp.zeros(m), params)
    closed = steered @ (np.asarray(f_z) - np.asarray(f_w) @ gain) @ steered.T
    radius = float(np.abs(np.linalg.eigvals(closed)).max())
    return -problem.dt / float(np.log(radius))


@functools.lru_cache(maxsize=16)
def _closed_loop(problem: WIPMProblem) -> Any:
    """The jitted rollout of :data:`CHUNK` steps of ``problem``'s dynamics under ``w =
    clip(-G (z - goal), -w_max, w_max)``: ``(z_1 .. z_CHUNK, a(z_0) .. a(z_{CHUNK-1}))`` from
    ``z_0``."""
    step, n = problem.dynamics(), problem.n_state

    def run(
        z0: jax.Array, gain: jax.Array, goal: jax.Array, w_max: jax.Array, params: WIPMParams
    ) -> tuple[jax.Array, jax.Array]:
        def body(z: jax.Array, _: None) -> tuple[jax.Array, tuple[jax.Array, jax.Array]]:
            w = jnp.clip(-gain @ (z - goal), -w_max, w_max)
            acceleration = problem.horizontal_acceleration(z[:n], z[n:], params)
            following = step(z, w, params)
            return following, (following, acceleration)

        _, (zs, accelerations) = jax.lax.scan(body, z0, None, length=CHUNK)
        return zs, accelerations

    return jax.jit(run)


def settle(
    problem: WIPMProblem,
    z_end: np.ndarray,
    goal: np.ndarray,
    params: WIPMParams,
    tolerance: float,
    max_steps: int,
    envelope: Envelope,
    stiffness: float,
    heading_free: bool = False,
) -> Settling:
    """The continuation from the plan's last DDP state ``z_end`` (``[s_N, u_N]``) toward
    ``goal`` (``[s_goal, 0]``; 3-D its heading ``goal[1]``, not steered to when
    ``heading_free``) under the rate-bounded feedback of the first rung of
    :func:`stiffness_ladder` (from ``stiffness``) that settles within ``envelope`` (module
    docstring): its states up to and including the first whose steered coordinates are all
    within ``tolerance`` of the goal's, within ``max_steps`` states. The envelope's
    acceleration and ``theta`` are widened to ``z_end``'s own where it starts beyond them.
    When no rung settles within it: the rung that settles going least beyond it, else the
    softest rung's rollout, with the ``failure``. Empty when ``z_end`` is already there, and,
    unsettled with its ``failure``, when there is no gain or the rollout is not finite."""
    n, m = problem.n_state, problem.n_control
    empty = Settling(np.zeros((0, n)), np.zeros((0, m)), np.zeros(0), True)
    steered = steered_coordinates(problem, float(goal[1]), heading_free)
    w_max = np.asarray(envelope.rate, dtype=float)
    if w_max.shape != (m,):
        raise ValueError(f"rate bounds of shape {w_max.shape}: expected ({m},)")

    def deviation(z: np.ndarray) -> np.ndarray:
        return np.abs((z - goal) @ steered.T).max(axis=-1)

    if deviation(z_end) <= tolerance:
        return empty
    least_beyond: tuple[float, Settling] | None = None
    result = empty
    for rung in stiffness_ladder(stiffness):
        try:
            gain = settling_gain(problem, goal, params, steered, rung)
        except ValueError as error:
            result = _unsettled(n, m, rung, str(error))
            continue
        result, excess = _rollout(
            problem, z_end, gain, goal, params, envelope, deviation, tolerance, max_steps, rung
        )
        if result.settled and result.failure is None:
            return result
        if result.settled and (least_beyond is None or excess < least_beyond[0]):
            least_beyond = (excess, result)
    return result if least_beyond is None else least_beyond[1]


def _unsettled(n: int, m: int, stiffness: float, failure: str) -> Settling:
    """An empty, unsettled continuation and why."""
    return Settling(np.zeros((0, n)), np.zeros((0, m)), np.zeros(0), False, stiffness, failure)


def _rollout(
    problem: WIPMProblem,
    z_end: np.ndarray,
    gain: np.ndarray,
    goal: np.ndarray,
    params: WIPMParams,
    envelope: Envelope,
    deviation: Callable[[np.ndarray], np.ndarray],
    tolerance: float,
    max_steps: int,
    stiffness: float,
) -> tuple[Settling, float]:
    """One rung's rollout (:func:`settle`), chunk after chunk, up to the first state within
    ``tolerance`` of the goal (settled) or ``max_steps`` states, and how far it goes beyond the
    envelope (widened to ``z_end``'s own acceleration and ``|theta|``): the largest ratio of
    its peak acceleration and ``|theta|`` to their bounds (beyond it above 1). Its
    ``failure`` says when it did not settle or went beyond; empty when it is not finite."""
    n, m, theta = problem.n_state, problem.n_control, problem.theta_index
    run, w_max = _closed_loop(problem), jnp.asarray(envelope.rate, dtype=float)
    zs: list[np.ndarray] = []
    accelerations: list[np.ndarray] = []
    z, count, settled = jnp.asarray(z_end), 0, False
    while count < max_steps:
        chunk, chunk_a = (np.asarray(a) for a in run(z, gain, goal, w_max, params))
        if not np.isfinite(chunk).all():
            diverged = f"at stiffness {stiffness:g}, not finite within {count + CHUNK} steps"
            return _unsettled(n, m, stiffness, diverged), float(np.inf)
        inside = np.flatnonzero(deviation(chunk) <= tolerance)
        keep = min(CHUNK, max_steps - count, int(inside[0]) + 1 if inside.size else CHUNK)
        settled = bool(inside.size) and int(inside[0]) < keep
        zs.append(chunk[:keep])
        accelerations.append(chunk_a[:keep])
        count += keep
        if settled:
            break
        z = jnp.asarray(chunk[-1])
    Z, A = np.concatenate(zs), np.concatenate(accelerations)
    theta_bound = max(envelope.theta, abs(float(z_end[theta])))
    acceleration_bound = max(envelope.acceleration, float(A[0]))  # A[0]: z_end's own
    peak_theta, peak_a = float(np.abs(Z[:, theta]).max()), float(A.max())
    excess = max(_ratio(peak_theta, theta_bound), _ratio(peak_a, acceleration_bound))
    failure: str | None = None
    if not settled:
        failure = f"not within {tolerance:g} of the goal in {max_steps} steps"
    elif peak_theta > theta_bound:
        failure = f"|theta| up to {peak_theta:.4f} rad, beyond the plan's {theta_bound:.4f}"
    elif peak_a > acceleration_bound:
        failure = (
            f"acceleration up to {peak_a:.4f} m/s^2, beyond the plan's {acceleration_bound:.4f}"
        )
    if failure is not None:
        failure = f"at stiffness {stiffness:g}, {failure}"
    controls = np.vstack([z_end[None, n:], Z[:-1, n:]])
    return Settling(Z[:, :n], controls, A, settled, stiffness, failure), excess


def _ratio(peak: float, bound: float) -> float:
    """``peak / bound``, 0 for no peak and ``inf`` for a peak over a zero bound."""
    if peak <= 0.0:
        return 0.0
    return peak / bound if bound > 0.0 else float(np.inf)
