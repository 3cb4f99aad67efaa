"""Tests of controllers/optimizer/ddp.py: autodiff derivatives, exactness on LQ problems (against an
independent numpy Riccati recursion), DDP vs iLQR on the planar wheeled inverted pendulum,
warm start, compiled-function reuse, regularisation of an indefinite Q_uu and input checks.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from controllers.optimizer.ddp import (
    DDPConfig,
    DDPResult,
    DDPSolver,
    _mirrored_upper,
    _symmetrised,
    ddp_solve,
    make_ddp_solver,
    riccati_step,
    rollout,
    trajectory_cost,
)

# Planar wheeled inverted pendulum, x = [theta, thetad, x, xd], u = [thetadd] (the 2-D model of
# docs/AUTHORS_CONFIG.md §2.7 with the brief's coefficients), explicit Euler as the authors did.
WIP_ALPHA, WIP_BETA, WIP_R, WIP_G = 1.5, 0.7, 0.25, 9.81
DT = 0.01
# Q is the authors' 2-D DDP weight (docs/AUTHORS_CONFIG.md §2.7). Their R = 0.01 and Qf = 1e4 make
# the Hessian of J(U) nearly singular (smallest eigenvalue ~5e-5 against J ~ 60): a cost converged
# to 1e-12 then pins U only to ~3e-4. R = 1 and Qf = 1e3 keep it at ~1e-2, so "same optimum" can be
# checked to 1e-5 in U.
WIP_Q = np.diag([1.0, 0.1, 0.1, 0.1])
WIP_RW = 1.0
WIP_QF = 1e3 * np.eye(4)
WIP_GOAL = np.array([0.0, 0.0, 1.0, 0.0])  # drive 1 m and come upright
WIP_X0 = np.array([0.4, 0.0, 0.0, 0.0])  # from a 0.4 rad lean


def wip_xdd(th, thd, a, params):
    alpha, beta = params["alpha"], params["beta"]
    num = WIP_G * jnp.sin(th) + WIP_R * jnp.sin(th) * thd**2 - (beta + WIP_R * jnp.cos(th)) * a
    return num / (alpha + jnp.cos(th))


def wip_dynamics(x, u, params):
    th, thd, _, xd = x
    a = u[0]
    return x + params["dt"] * jnp.array([thd, a, xd, wip_xdd(th, thd, a, params)])


def wip_running(x, u, ref):
    e = x - ref
    return DT * 0.5 * (e @ WIP_Q @ e + WIP_RW * u @ u)


def wip_terminal(x, ref):
    e = x - ref
    return 0.5 * e @ WIP_QF @ e


WIP_PARAMS = {"alpha": WIP_ALPHA, "beta": WIP_BETA, "dt": DT}
WIP_N = 50
WIP_REFS = np.tile(WIP_GOAL, (WIP_N + 1, 1))
TIGHT = {"tolerance": 1e-12, "max_iterations": 100}
DDP_CONFIG = DDPConfig(second_order=True, **TIGHT)
ILQR_CONFIG = DDPConfig(second_order=False, **TIGHT)


@pytest.fixture(scope="module")
def wip_solutions() -> dict[str, DDPResult]:
    """DDP (through the cached one-shot ``ddp_solve``) and iLQR from the same zero warm start."""
    U0 = np.zeros((WIP_N, 1))
    ddp = ddp_solve(
        wip_dynamics, wip_running, wip_terminal, WIP_X0, U0, WIP_PARAMS, WIP_REFS, DDP_CONFIG
    )
    ilqr = make_ddp_solver(wip_dynamics, wip_running, wip_terminal, ILQR_CONFIG)(
        WIP_X0, U0, WIP_PARAMS, WIP_REFS
    )
    return {"ddp": ddp, "ilqr": ilqr}


# ------------------------------------------------------------------------- 1. derivatives
def _numpy_total_cost(U: np.ndarray, x0: np.ndarray, refs: np.ndarray, dt: float) -> float:
    """Independent numpy evaluation of the WIP cost (no JAX)."""
    x = x0.copy()
    total = 0.0
    for k in range(U.shape[0]):
        th, thd, _, xd = x
        a = U[k, 0]
        xdd = (
            WIP_G * np.sin(th) + WIP_R * np.sin(th) * thd**2 - (WIP_BETA + WIP_R * np.cos(th)) * a
        ) / (WIP_ALPHA + np.cos(th))
        e = x - refs[k]
        total += DT * 0.5 * (e @ WIP_Q @ e + WIP_RW * a * a)  # running weight uses DT
        x = x + dt * np.array([thd, a, xd, xdd])
    e = x - refs[-1]
    return float(total + 0.5 * e @ WIP_QF @ e)


def test_cost_gradient_and_hessian_match_finite_differences() -> None:
    horizon, dt = 8, 0.1  # a coarse step makes the problem strongly nonlinear in U
    params = {**WIP_PARAMS, "dt": dt}
    x0 = np.array([0.6, -0.4, 0.1, 0.3])
    refs = np.tile(WIP_GOAL, (horizon + 1, 1))
    U = np.random.default_rng(0).normal(scale=1.0, size=(horizon, 1))

    def total(Uj):
        X = rollout(wip_dynamics, jnp.asarray(x0), Uj, params)
        return trajectory_cost(wip_running, wip_terminal, X, Uj, jnp.asarray(refs))

    value, grad, hess = jax.jit(lambda v: (total(v), jax.grad(total)(v), jax.hessian(total)(v)))(
        jnp.asarray(U)
    )
    # the JAX total cost is the numpy one
    np.testing.assert_allclose(float(value), _numpy_total_cost(U, x0, refs, dt), rtol=1e-13)
    grad = np.asarray(grad).ravel()
    hess = np.asarray(hess).reshape(horizon, horizon)

    def J(v: np.ndarray) -> float:
        return _numpy_total_cost(v.reshape(horizon, 1), x0, refs, dt)

    u = U.ravel()
    eye = np.eye(horizon)
    h1 = 1e-5
    grad_fd = np.array([(J(u + h1 * e) - J(u - h1 * e)) / (2 * h1) for e in eye])
    h2 = 1e-3
    hess_fd = np.array(
        [
            [
                (
                    J(u + h2 * ei + h2 * ej)
                    - J(u + h2 * ei - h2 * ej)
                    - J(u - h2 * ei + h2 * ej)
                    + J(u - h2 * ei - h2 * ej)
                )
                / (4 * h2 * h2)
                for ej in eye
            ]
            for ei in eye
        ]
    )
    grad_err = np.max(np.abs(grad - grad_fd)) / np.max(np.abs(grad))
    hess_err = np.max(np.abs(hess - hess_fd)) / np.max(np.abs(hess))
    print(f"relative FD errors: gradient {grad_err:.2e}, Hessian {hess_err:.2e}")
    assert grad_err < 1e-6
    assert hess_err < 1e-6
    assert np.allclose(hess, hess.T, rtol=0, atol=1e-12 * np.max(np.abs(hess)))

    # The solver's adjoint recursion gives the same gradient (max_iterations = 0: no step).
    probe = make_ddp_solver(wip_dynamics, wip_running, wip_terminal, DDPConfig(max_iterations=0))
    res = probe(x0, U, params, refs)
    assert int(res.iterations) == 0
    np.testing.assert_allclose(float(res.grad_norm), np.max(np.abs(grad)), rtol=1e-12)
    np.testing.assert_allclose(float(res.cost), J(u), rtol=1e-13)


@pytest.mark.parametrize(
    "settings",
    [
        {"max_iterations": 20, "tolerance": 1e-9},  # DDP, stops on the predicted decrease
        {  # the MPC's settings: iLQR, a budget of 2, no final backward pass
            "max_iterations": 2,
            "tolerance": 0.0,
            "second_order": False,
            "final_backward": False,
        },
    ],
)
def test_without_the_gradient_norm_the_solve_is_the_same(settings: dict[str, Any]) -> None:
    """``gradient_norm=False`` skips the adjoint recursion: ``grad_norm`` is NaN, and the
    trajectory, gains, costs and iteration count are those of the solve with it, to the bit
    (the stopping test on the predicted decrease is untouched)."""
    x0, horizon = np.array([0.4, -0.3, 0.2, 0.1]), 40
    refs = np.tile(WIP_GOAL, (horizon + 1, 1))
    U0 = np.zeros((horizon, 1))
    results = {
        flag: make_ddp_solver(
            wip_dynamics, wip_running, wip_terminal, DDPConfig(**settings, gradient_norm=flag)
        )(x0, U0, WIP_PARAMS, refs)
        for flag in (True, False)
    }
    with_norm, without = results[True], results[False]
    assert np.isfinite(float(with_norm.grad_norm)) and np.isnan(float(without.grad_norm))
    assert int(with_norm.iterations) > 1
    for name in ("X", "U", "K", "k", "cost_history", "mu_history", "iterations", "converged"):
        np.testing.assert_array_equal(getattr(without, name), getattr(with_norm, name))
    with pytest.raises(ValueError, match="needs gradient_norm"):
        DDPConfig(grad_tolerance=1e-6, gradient_norm=False)


# ------------------------------------------------------------------------- 2. LQ = Riccati
def _lq_problem(horizon: int):
    rng = np.random.default_rng(horizon)
    n, m, dt = 4, 2, 0.05
    # mildly open-loop unstable (a fast unstable A would blow up the zero-control rollout over
    # N = 200 and cost the affine terms digits through cancellation)
    A = np.eye(n) + dt * np.array(
        [[0, 1, 0, 0], [0.2, -0.1, 0.5, 0], [0, 0, 0, 1], [0.3, 0, -1.0, -0.2]]
    )
    B = dt * rng.normal(size=(n, m))
    Q = np.diag([2.0, 0.5, 1.0, 0.2])
    R = np.array([[0.3, 0.05], [0.05, 0.2]])
    Qf = 50.0 * np.eye(n)
    t = np.arange(horizon + 1) * dt
    refs = {
        "x": np.stack([np.sin(t), np.cos(t), 0.5 * t, np.ones_like(t)], axis=1),
        "u": np.stack([0.1 * np.cos(2 * t), -0.2 * np.ones_like(t)], axis=1),
    }
    x0 = np.array([0.4, -0.3, 1.0, 0.0])
    return A, B, Q, R, Qf, refs, x0


def _numpy_tracking_lqr(A, B, Q, R, Qf, refs, x0):
    """Time-varying LQR with tracking terms: V_k(x) = 1/2 x'P x + p'x + c, u = K x + kff."""
    horizon = refs["u"].shape[0] - 1
    rx, ru = refs["x"], refs["u"]
    P = Qf
    p = -Qf @ rx[horizon]
    c = 0.5 * rx[horizon] @ Qf @ rx[horizon]
    Ks, kffs = [None] * horizon, [None] * horizon
    for k in reversed(range(horizon)):
        quu = R + B.T @ P @ B
        qux = B.T @ P @ A
        qu = -R @ ru[k] + B.T @ p
        qx = -Q @ rx[k] + A.T @ p
        K = -np.linalg.solve(quu, qux)
        kff = -np.linalg.solve(quu, qu)
        c = c + 0.5 * rx[k] @ Q @ rx[k] + 0.5 * ru[k] @ R @ ru[k] + 0.5 * kff @ qu
        P = Q + A.T @ P @ A + qux.T @ K
        P = 0.5 * (P + P.T)
        p = qx + qux.T @ kff
        Ks[k], kffs[k] = K, kff
    xs, us = [x0], []
    for k in range(horizon):
        us.append(Ks[k] @ xs[-1] + kffs[k])
        xs.append(A @ xs[-1] + B @ us[-1])
    optimal_cost = 0.5 * x0 @ P @ x0 + p @ x0 + c
    return np.array(xs), np.array(us), np.array(Ks), float(optimal_cost)


@pytest.mark.parametrize("horizon", [30, 200])
def test_lq_problem_one_iteration_equals_riccati(horizon: int) -> None:
    A, B, Q, R, Qf, refs, x0 = _lq_problem(horizon)
    Aj, Bj = jnp.asarray(A), jnp.asarray(B)

    def dynamics(x, u, params):
        return Aj @ x + Bj @ u

    def running(x, u, ref):
        ex, eu = x - ref["x"], u - ref["u"]
        return 0.5 * (ex @ Q @ ex + eu @ R @ eu)

    def terminal(x, ref):
        e = x - ref["x"]
        return 0.5 * e @ Qf @ e

    config = DDPConfig(mu_init=0.0, mu_min=0.0, tolerance=1e-10)
    res = make_ddp_solver(dynamics, running, terminal, config)(
        x0, np.zeros((horizon, 2)), None, refs
    )
    X_ref, U_ref, K_ref, cost_ref = _numpy_tracking_lqr(A, B, Q, R, Qf, refs, x0)

    # "One iteration" = one line search (accepting alpha = 1) + the backward pass at the new
    # trajectory, which predicts no further decrease: the solve stops there, converged.
    hist = np.asarray(res.cost_history)
    assert bool(res.converged)
    assert int(res.iterations) == 1
    assert hist[0] > hist[1]
    assert np.all(hist[1:] == hist[1])
    assert np.all(np.asarray(res.mu_history) == 0.0)  # regularisation really off

    u_err = np.max(np.abs(np.asarray(res.U) - U_ref))
    x_err = np.max(np.abs(np.asarray(res.X) - X_ref))
    K_err = np.max(np.abs(np.asarray(res.K) - K_ref))
    k_max = np.max(np.abs(np.asarray(res.k)))
    cost_err = abs(float(res.cost) - cost_ref) / abs(cost_ref)
    print(
        f"N={horizon}: |U-U_lqr| {u_err:.1e}, |X-X_lqr| {x_err:.1e}, |K-K_lqr| {K_err:.1e}, "
        f"max|k| {k_max:.1e}, cost rel err {cost_err:.1e}, grad {float(res.grad_norm):.1e}"
    )
    assert u_err < 1e-9
    assert x_err < 1e-9
    assert K_err < 1e-9
    assert k_max < 1e-9
    assert cost_err < 1e-12


@pytest.mark.parametrize(("n", "m", "second_order"), [(8, 2, False), (8, 2, True), (4, 1, False)])
def test_riccati_step_equals_the_textbook_step(n: int, m: int, second_order: bool) -> None:
    """One step of (2)-(5) on random derivatives against NumPy's matrix products: the step
    computes the symmetric products' upper triangles only (``_mirrored_upper``); its ``V_xx``
    is exactly symmetric."""
    rng = np.random.default_rng(n + m + second_order)

    def symmetric(size: int, shift: float = 0.0) -> np.ndarray:
        a = rng.normal(size=(size, size))
        return a @ a.T + shift * np.eye(size)

    lx, lu = rng.normal(size=n), rng.normal(size=m)
    lxx, luu, lux = symmetric(n), symmetric(m, 1.0), rng.normal(size=(m, n))
    fx, fu = np.eye(n) + 0.1 * rng.normal(size=(n, n)), rng.normal(size=(n, m))
    vx, vxx, mu = rng.normal(size=n), symmetric(n), 0.3
    derivatives = [lx, lu, lxx, lux, luu, fx, fu]
    qx, qu = lx + fx.T @ vx, lu + fu.T @ vx
    qxx, qux, quu = lxx + fx.T @ vxx @ fx, lux + fu.T @ vxx @ fx, luu + fu.T @ vxx @ fu
    if second_order:
        fxx = rng.normal(size=(n, n, n))
        fxx = fxx + fxx.transpose(0, 2, 1)
        fux, fuu = rng.normal(size=(n, m, n)), rng.normal(size=(n, m, m))
        fuu = fuu + fuu.transpose(0, 2, 1)
        derivatives += [fxx, fux, fuu]
        qxx = qxx + np.einsum("i,ijk->jk", vx, fxx)
        qux = qux + np.einsum("i,ijk->jk", vx, fux)
        quu = quu + np.einsum("i,ijk->jk", vx, fuu)
    gains = -np.linalg.solve(quu + mu * np.eye(m), np.column_stack([qu, qux]))
    k, K = gains[:, 0], gains[:, 1:]
    want = (
        qx + K.T @ quu @ k + K.T @ qu + qux.T @ k,
        qxx + K.T @ quu @ K + K.T @ qux + qux.T @ K,
        K,
        k,
        k @ qu,
        0.5 * k @ quu @ k,
    )
    got = riccati_step(
        tuple(jnp.asarray(d) for d in derivatives),
        jnp.asarray(vx),
        jnp.asarray(vxx),
        jnp.asarray(mu),
        second_order,
    )
    for name, value, expected in zip(
        ("V_x", "V_xx", "K", "k", "dV_1", "dV_2"), got[:6], want, strict=True
    ):
        scale = max(1.0, float(np.max(np.abs(expected))))
        np.testing.assert_allclose(
            np.asarray(value), expected, rtol=0, atol=1e-12 * scale, err_msg=name
        )
    assert bool(got[6])
    vxx_new = np.asarray(got[1])
    assert np.array_equal(vxx_new, vxx_new.T)


def test_mirrored_upper_keeps_the_upper_triangle_and_symmetrised_keeps_a_symmetric_matrix() -> None:
    a = np.random.default_rng(3).normal(size=(5, 5))
    mirrored = np.asarray(_mirrored_upper(jnp.asarray(a)))
    upper = np.triu_indices(5)
    np.testing.assert_array_equal(mirrored[upper], a[upper])  # the upper triangle, to the bit
    np.testing.assert_array_equal(mirrored, mirrored.T)
    s = a + a.T  # exactly symmetric: unchanged to the bit
    np.testing.assert_array_equal(np.asarray(_symmetrised(jnp.asarray(s))), s)
    np.testing.assert_array_equal(np.asarray(_symmetrised(jnp.asarray(a))), 0.5 * (a + a.T))


# ------------------------------------------------------------------------- 3. DDP vs iLQR
def test_ddp_and_ilqr_reach_the_same_optimum(wip_solutions: dict[str, DDPResult]) -> None:
    ddp, ilqr = wip_solutions["ddp"], wip_solutions["ilqr"]
    assert bool(ddp.converged) and bool(ilqr.converged)
    cost_rel = abs(float(ddp.cost) - float(ilqr.cost)) / abs(float(ilqr.cost))
    u_err = np.max(np.abs(np.asarray(ddp.U) - np.asarray(ilqr.U)))
    print(
        f"DDP {int(ddp.iterations)} iterations, iLQR {int(ilqr.iterations)}; "
        f"cost {float(ddp.cost):.12g} vs {float(ilqr.cost):.12g} (rel {cost_rel:.1e}); "
        f"max|dU| {u_err:.1e}; initial cost {float(ddp.cost_history[0]):.6g}"
    )
    assert cost_rel < 1e-8
    assert u_err < 1e-5
    assert int(ddp.iterations) <= int(ilqr.iterations)
    # the solution is a real improvement and a stationary point
    assert float(ddp.cost) < 0.5 * float(ddp.cost_history[0])
    assert float(ddp.grad_norm) < 1e-5
    # monotone cost histories, padded with the final value after the stop
    for res in (ddp, ilqr):
        hist = np.asarray(res.cost_history)
        assert np.all(np.diff(hist) <= 0)
        assert np.all(hist[int(res.iterations) :] == float(res.cost))
    # X is the rollout of U
    X = rollout(wip_dynamics, jnp.asarray(WIP_X0), ddp.U, WIP_PARAMS)
    np.testing.assert_allclose(np.asarray(ddp.X), np.asarray(X), rtol=0, atol=1e-14)


# ------------------------------------------------------------------------- 4. warm start
def test_warm_start_from_the_optimum_returns_immediately(
    wip_solutions: dict[str, DDPResult],
) -> None:
    first = wip_solutions["ddp"]
    # same functions and config: ddp_solve reuses the cached compiled solver
    again = ddp_solve(
        wip_dynamics, wip_running, wip_terminal, WIP_X0, first.U, WIP_PARAMS, WIP_REFS, DDP_CONFIG
    )
    print(f"warm start: {int(again.iterations)} iterations, cost {float(again.cost):.12g}")
    assert int(again.iterations) <= 1
    assert bool(again.converged)
    np.testing.assert_allclose(float(again.cost), float(first.cost), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(again.U), np.asarray(first.U), rtol=0, atol=1e-9)


# ------------------------------------------------------------------------- 5. reuse
def test_same_shapes_reuse_one_compiled_function() -> None:
    solver = make_ddp_solver(
        wip_dynamics, wip_running, wip_terminal, DDPConfig(second_order=False, max_iterations=5)
    )
    assert isinstance(solver, DDPSolver)
    U0 = np.zeros((20, 1))
    refs = np.tile(WIP_GOAL, (21, 1))
    a = solver(WIP_X0, U0, WIP_PARAMS, refs)
    b = solver(np.array([0.1, 0.0, 0.0, 0.0]), np.asarray(a.U), WIP_PARAMS, refs)
    # a new params *value* with the same structure is not a new shape either
    c = solver(WIP_X0, U0, {**WIP_PARAMS, "alpha": 1.6}, refs)
    assert solver.trace_count == 1
    assert solver.jitted._cache_size() == 1
    assert float(a.cost) != float(c.cost)
    assert np.all(np.isfinite(np.asarray(b.U)))
    # a new horizon is a new shape: exactly one more trace
    solver(WIP_X0, np.zeros((21, 1)), WIP_PARAMS, np.tile(WIP_GOAL, (22, 1)))
    assert solver.trace_count == 2


# ------------------------------------------------------------------------- 6. indefinite Q_uu
WELL = 1000.0  # weight of a double-well control cost: l_uu = -WELL dt at u = 0


def nonconvex_running(x, u, ref):
    return wip_running(x, u, ref) + DT * WELL * jnp.sum(0.25 * u**4 - 0.5 * u**2)


def test_indefinite_quu_is_regularised() -> None:
    config = DDPConfig(mu_init=0.0, mu_min=1e-6, max_iterations=60)
    solver = make_ddp_solver(wip_dynamics, nonconvex_running, wip_terminal, config)
    res = solver(WIP_X0, np.zeros((WIP_N, 1)), WIP_PARAMS, WIP_REFS)
    mu_path = np.asarray(res.mu_history)[: int(res.iterations) + 1]
    hist = np.asarray(res.cost_history)
    print(
        f"indefinite Q_uu: {int(res.iterations)} iterations, converged {bool(res.converged)}, "
        f"cost {hist[0]:.6g} -> {float(res.cost):.6g}, mu path {mu_path}"
    )
    # at U = 0 the Hessian of the control cost is -WELL*DT: the first pass needed mu > 0
    assert mu_path[0] > 0.0
    for leaf in (res.X, res.U, res.K, res.k, res.cost):
        assert np.all(np.isfinite(np.asarray(leaf)))
    assert float(res.cost) < hist[0]
    assert bool(res.converged)
    # ends near a well bottom (|u| ~ 1) for most of the horizon
    assert np.median(np.abs(np.asarray(res.U))) > 0.5

    # With regularisation switched off (mu = mu_min = 0) the same start cannot proceed: the
    # solve stops at once, unconverged, and returns the warm start untouched.
    off = make_ddp_solver(
        wip_dynamics, nonconvex_running, wip_terminal, DDPConfig(mu_init=0.0, mu_min=0.0)
    )(WIP_X0, np.zeros((WIP_N, 1)), WIP_PARAMS, WIP_REFS)
    assert not bool(off.converged)
    assert int(off.iterations) == 0
    assert np.all(np.asarray(off.U) == 0.0)


# ------------------------------------------------------------------------- 7. bad inputs
def test_bad_inputs_raise_value_error() -> None:
    solver = make_ddp_solver(wip_dynamics, wip_running, wip_terminal, DDPConfig(max_iterations=3))
    U0 = np.zeros((10, 1))
    refs = np.tile(WIP_GOAL, (11, 1))
    with pytest.raises(ValueError, match="U_init must have shape"):
        solver(WIP_X0, np.zeros(10), WIP_PARAMS, refs)
    with pytest.raises(ValueError, match="leading axis of length N\\+1"):
        solver(WIP_X0, np.zeros((12, 1)), WIP_PARAMS, refs)
    with pytest.raises(ValueError, match="x0 contains non-finite"):
        solver(np.array([np.nan, 0.0, 0.0, 0.0]), U0, WIP_PARAMS, refs)
    with pytest.raises(ValueError, match="x0 must be a non-empty 1-D"):
        solver(WIP_X0[None], U0, WIP_PARAMS, refs)
    with pytest.raises(ValueError, match="U_init contains non-finite"):
        solver(WIP_X0, np.full((10, 1), np.inf), WIP_PARAMS, refs)

    def bad_dynamics(x, u, params):
        return x[:2]

    with pytest.raises(ValueError, match="dynamics"):
        make_ddp_solver(bad_dynamics, wip_running, wip_terminal)(WIP_X0, U0, WIP_PARAMS, refs)
    with pytest.raises(ValueError, match="mu_factor"):
        DDPConfig(mu_factor=1.0)
    with pytest.raises(ValueError, match="alphas"):
        DDPConfig(alphas=(0.5, 1.0))
    assert solver.trace_count == 0  # nothing above reached the compiled code
