"""The offline plan's continuation past its end (docs/controllers.md §3.1).

A plan over a finite horizon ends where its terminal cost left it, which on a short or
aggressive drive is not the goal: on PlanarTray-v0 with ``goal = 1``, ``horizon_s = 3`` and no
acceleration cap it ends 12.7 mrad back, 2.7 mm short and still braking at ``thdd = -1.24``
rad/s^2. A reference that steps from there to the goal at ``t_f`` is answered by the MPC with
a jolt (its ``thdd`` doubled to -7 rad/s^2 there, the axle's acceleration 4.5 m/s^2 for
~50 ms).

:func:`settle` continues the plan from its last DDP state ``z_N = [s_N, u_N]`` (the control
is part of the plan's state, so it does not jump) under a constant feedback on the control's
rate, ``w = -G (z - z_goal)``, rolled out on the plan's own discrete dynamics (the nonlinear
WIPM, explicit Euler, the plan's ``lambda(q)``) until every coordinate it steers is within a
tolerance of the goal. ``G`` is the plan's own problem, linearised at the goal at rest, solved
as a receding horizon (:func:`settling_gain`): the plan's running cost, terminal weights and
horizon, the Riccati recursion run back over that horizon, its first step's gain. Each step of
the continuation is thus the first step of the plan re-planned from there (to first order about
the goal), and as brisk as the plan: the same weights over a 3 s horizon settle with a time
constant of 0.87 s, over 20 s (converged: the infinite-horizon LQR) 1.43 s (PlanarTray-v0).
The continuation is dynamically consistent with the plan; the penalties on acceleration and
``theta`` are not in the linearised problem, so the plan checks the continuation against its
bounds.

A continuation recovers from where the plan left off: from a plan that ends braking hard (the
example above), with a control that cannot jump, it swings back to 0.864 m, 13 cm behind where
the plan ended, and is within 1 cm and 1 cm/s of the goal 4.3 s after ``t_f``
(docs/controllers.md §3.1 has the closed loop's numbers).

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
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from controllers.simplified.wipm import WIPMParams
from controllers.simplified.wipm_problem import WIPMProblem

#: rollout steps per compiled call: the continuation is rolled out in chunks of this many
#: steps until it settles (one compilation per problem, whatever its length)
CHUNK = 500


@dataclass(frozen=True)
class Settling:
    """A continuation of ``K`` steps past the plan's last state ``z_N``.

    Attributes:
        states: (K, n) the WIPM states at steps ``N+1 .. N+K``.
        controls: (K, m) the controls at steps ``N .. N+K-1`` (the first is ``z_N``'s).
        accelerations: (K,) the axle's horizontal acceleration at steps ``N .. N+K-1``.
        settled: whether it ended within the tolerance (else it stopped at the step budget,
            or, non-finite or without a gain, it is empty).
        failure: why it is empty or unsettled, or None.
    """

    states: np.ndarray
    controls: np.ndarray
    accelerations: np.ndarray
    settled: bool
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


def settling_gain(
    problem: WIPMProblem, goal: np.ndarray, params: WIPMParams, steered: np.ndarray, steps: int
) -> np.ndarray:
    """The gain ``G`` (``m`` x ``n + m``, zero on what is not steered) of the plan's own problem
    linearised at ``goal`` (``z`` at rest, zero control and rate) and solved over its horizon of
    ``steps`` steps, as a receding horizon: the first step's feedback of the finite-horizon LQR
    with the plan's running cost (``dt`` times its weights) and terminal weights, the Riccati
    recursion run back from the terminal cost. ``w = -G (z - goal)`` is the first rate the plan's
    DDP, run again from ``z`` over its horizon, would give to first order about the goal. The
    recursion stops early once it has converged (a horizon long against the model's time
    constants: the gain is then the infinite-horizon LQR's). ``ValueError`` when the gain does
    not stabilise the linearised model."""
    m = problem.n_control
    f_z, f_w = problem.dynamics_derivatives()(jnp.asarray(goal), jnp.zeros(m), params)
    A = steered @ np.asarray(f_z) @ steered.T
    B = steered @ np.asarray(f_w)
    weights, dt = problem.weights, problem.dt
    Q = dt * steered @ np.diag(np.concatenate([weights.q, weights.r])) @ steered.T
    R = dt * np.diag(np.asarray(weights.r_rate, dtype=float))
    P = steered @ np.diag(np.concatenate([weights.q_terminal, np.zeros(m)])) @ steered.T
    gain = np.zeros((m, A.shape[0]))
    for _ in range(steps):
        gain = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
        following = Q + A.T @ P @ (A - B @ gain)
        following = 0.5 * (following + following.T)
        converged = np.abs(following - P).max() <= 1e-13 * np.abs(following).max()
        P = following
        if converged:
            break
    radius = float(np.abs(np.linalg.eigvals(A - B @ gain)).max())
    if not radius < 1.0:
        raise ValueError(
            f"the plan's problem over {steps} steps, linearised at the goal, gives a feedback "
            f"that does not settle (spectral radius {radius:.6f})"
        )
    return np.asarray(gain @ steered)


@functools.lru_cache(maxsize=16)
def _closed_loop(problem: WIPMProblem) -> Any:
    """The jitted rollout of :data:`CHUNK` steps of ``problem``'s dynamics under ``w = -G (z -
    goal)``: ``(z_1 .. z_CHUNK, a(z_0) .. a(z_{CHUNK-1}))`` from ``z_0``."""
    step, n = problem.dynamics(), problem.n_state

    def run(
        z0: jax.Array, gain: jax.Array, goal: jax.Array, params: WIPMParams
    ) -> tuple[jax.Array, jax.Array]:
        def body(z: jax.Array, _: None) -> tuple[jax.Array, tuple[jax.Array, jax.Array]]:
            w = -gain @ (z - goal)
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
    horizon: int,
    heading_free: bool = False,
) -> Settling:
    """The continuation from the plan's last DDP state ``z_end`` (``[s_N, u_N]``) toward
    ``goal`` (``[s_goal, 0]``; 3-D its heading ``goal[1]``, not steered to when
    ``heading_free``) under :func:`settling_gain` of the plan's ``horizon`` (steps), up to
    and including the first state whose steered coordinates are all within ``tolerance`` of the
    goal's, or ``max_steps`` states. Empty when ``z_end`` is already there, and, unsettled with
    its ``failure``, when there is no gain or the rollout is not finite."""
    n, m = problem.n_state, problem.n_control
    empty = Settling(np.zeros((0, n)), np.zeros((0, m)), np.zeros(0), True)
    steered = steered_coordinates(problem, float(goal[1]), heading_free)

    def deviation(z: np.ndarray) -> np.ndarray:
        return np.abs((z - goal) @ steered.T).max(axis=-1)

    if deviation(z_end) <= tolerance:
        return empty
    try:
        gain = settling_gain(problem, goal, params, steered, horizon)
    except ValueError as error:
        return Settling(empty.states, empty.controls, empty.accelerations, False, str(error))
    run = _closed_loop(problem)
    zs: list[np.ndarray] = []
    accelerations: list[np.ndarray] = []
    z, count, settled = jnp.asarray(z_end), 0, False
    while count < max_steps:
        chunk, chunk_a = (np.asarray(a) for a in run(z, gain, goal, params))
        if not np.isfinite(chunk).all():
            diverged = f"its rollout is not finite within {count + CHUNK} steps"
            return Settling(empty.states, empty.controls, empty.accelerations, False, diverged)
        inside = np.flatnonzero(deviation(chunk) <= tolerance)
        keep = min(CHUNK, max_steps - count, int(inside[0]) + 1 if inside.size else CHUNK)
        settled = bool(inside.size) and int(inside[0]) < keep
        zs.append(chunk[:keep])
        accelerations.append(chunk_a[:keep])
        count += keep
        if settled:
            break
        z = jnp.asarray(chunk[-1])
    Z = np.concatenate(zs)
    controls = np.vstack([z_end[None, n:], Z[:-1, n:]])
    failure = None if settled else f"not within {tolerance:g} of the goal in {max_steps} steps"
    return Settling(Z[:, :n], controls, np.concatenate(accelerations), settled, failure)
