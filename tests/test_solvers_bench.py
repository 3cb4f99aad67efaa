"""``wip-bench solvers``: the CLI runs, writes the JSON schema, and every
peer reaches our optimum: crocoddyl and the NumPy iLQR on the WIPM (converged costs within 1e-6
relative), the QP peers on recorded task QPs (solutions within 1e-6). No timing assertions."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks.cli import main
from benchmarks.speed.crocoddyl_wipm import CrocoddylWIPM
from benchmarks.speed.ddp_bench import (
    CROCODDYL_TH_STOP_CONVERGED,
    GOALS,
    goal_state,
    initial_state,
    krang_params,
)
from benchmarks.speed.numpy_ilqr import NumpyILQR
from benchmarks.speed.qp_peers import all_solvers, reference_solution, solution_error
from benchmarks.speed.qp_recording import RecordedQP
from controllers.high_level.mpc import MPCConfig, mpc_problem
from controllers.high_level.planning import PlanConfig, planning_problem
from controllers.simplified.wipm_problem import ddp_solver_for, refs_for

PROBLEMS = ("planar", "3d")
DDP_SOLVERS = ("ours", "crocoddyl", "numpy_ilqr")
QP_ENVS = ("planar", "krang")
QP_SOLVERS = ("proxqp", "proxqp_shortcut", "osqp", "daqp", "quadprog", "slsqp")
REQUIRED_RATIOS = {
    f"{kind}_{p}" for kind in ("crocoddyl_plan", "crocoddyl_mpc", "numpy_plan") for p in PROBLEMS
} | {f"qp_{s}_{env}" for s in QP_SOLVERS[2:] for env in QP_ENVS}


def stats_ok(entry: dict[str, float]) -> bool:
    return (
        set(entry) >= {"median", "p99"}
        and all(isinstance(v, int | float) and math.isfinite(v) and v > 0 for v in entry.values())
        and entry["p99"] >= entry["median"]
    )


def test_quick_run_schema_and_agreement(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "solvers.json"
    assert main(["solvers", "--quick", "--json", str(path)]) == 0
    printed = capsys.readouterr().out
    assert "| planar | crocoddyl |" in printed and "| krang | slsqp |" in printed
    results = json.loads(path.read_text())
    for key in ("ddp_plan_ms", "ddp_iter_ms", "mpc_step_ms"):
        assert set(results[key]) == set(PROBLEMS), key
        for p in PROBLEMS:
            assert set(results[key][p]) == set(DDP_SOLVERS), (key, p)
            for s in DDP_SOLVERS:
                assert stats_ok(results[key][p][s]), (key, p, s, results[key][p][s])
    for p in PROBLEMS:
        for s in DDP_SOLVERS:
            compile_s = results["compile_s"][p][s]
            assert all(math.isfinite(v) and v >= 0 for v in compile_s.values()), (p, s)
    assert set(results["qp_solve_us"]) == set(QP_ENVS)
    for env in QP_ENVS:
        assert set(results["qp_solve_us"][env]) == set(QP_SOLVERS)
        for s in QP_SOLVERS:
            assert stats_ok(results["qp_solve_us"][env][s]), (env, s)
    assert set(results["ratios"]) >= REQUIRED_RATIOS
    for key in REQUIRED_RATIOS:
        value = results["ratios"][key]
        assert isinstance(value, float) and math.isfinite(value) and value > 0, key
    assert set(results["ratios_controller_path"]) == {
        f"qp_{s}_{env}" for s in QP_SOLVERS[2:] for env in QP_ENVS
    }
    for key in (
        "qp_krang_under_40us",
        "qp_krang_within_2x_fastest_peer",
        "plan_under_10ms_3d",
        "qp_krang_under_40us_controller_path",
    ):
        assert set(results["targets"][key]) == {"figure", "limit", "met"}, key
    unit = results["reference_step_us"]
    assert math.isfinite(unit) and unit > 0
    for p in PROBLEMS:
        units = results["mpc_step_units"][p]
        assert units["median"] == pytest.approx(
            results["mpc_step_ms"][p]["ours"]["median"] * 1e3 / unit
        )
    for key in (
        "mpc_step_under_15_units_3d",
        "mpc_step_under_8_units_planar",
        "mpc_step_p99_under_2x_median_3d",
        "plan_under_50ms_3d",
    ):
        assert set(results["targets"][key]) == {"figure", "limit", "met"}, key
    # the optimum checks: every DDP solver converged to the same cost
    for p in PROBLEMS:
        for what in ("plan", "mpc_step"):
            check = results["optimum_checks"]["ddp"][p][what]
            assert check["agree"] is True and check["max_rel_diff"] <= 1e-6, (p, what)
    # every QP solver reached the reference (SLSQP included, on these QPs)
    for env in QP_ENVS:
        assert results["qp"][env]["qps"] >= 10
        for s in QP_SOLVERS:
            check = results["optimum_checks"]["qp"][env][s]
            assert check["agree"] is True and check["failures"] == 0, (env, s, check)
            assert check["max_error"] <= 1e-6


@pytest.mark.parametrize("problem", PROBLEMS)
def test_crocoddyl_model_reaches_our_plan_optimum(problem: str) -> None:
    """The Python action model is the same problem: on a short plan (N = 300) crocoddyl's
    converged cost is ours to 1e-6 relative, and its states follow ours."""
    params, theta0 = krang_params()
    config = PlanConfig(horizon_s=3.0)
    state = initial_state(problem, theta0)
    goal = goal_state(problem, state, np.asarray(GOALS[problem]))
    wipm = planning_problem(problem == "planar", config, 1.0, heading_given=False)
    steps, m = config.steps, wipm.n_control
    z0 = np.concatenate([state, np.zeros(m)])
    U0 = np.zeros((steps, m))
    goals = np.tile(goal, (steps + 1, 1))
    ours = ddp_solver_for(wipm, config.ddp)(z0, U0, params, refs_for(goals, params))
    assert bool(ours.converged)
    peer = CrocoddylWIPM(wipm, params, steps, config.ddp.mu_init).solve(
        z0, U0, params, goals, 500, 1e-9
    )
    assert peer.converged
    assert abs(peer.cost - float(ours.cost)) <= 1e-6 * abs(float(ours.cost))
    # the same dynamics: the returned states are the rollout of the returned controls
    assert peer.X.shape == np.asarray(ours.X).shape
    assert np.isclose(peer.initial_cost, float(ours.cost_history[0]), rtol=1e-12)


def test_crocoddyl_mpc_step_matches_numpy_ilqr_cost() -> None:
    """One MPC-problem step (no rate input) from a zero warm start, run to convergence by
    crocoddyl and the NumPy iLQR: the same cost to 1e-6 relative."""
    params, theta0 = krang_params()
    config = MPCConfig()
    wipm = mpc_problem(True, config, 1.0, 0.25)
    horizon = config.steps
    x0 = np.array([theta0, 0.0, 0.0, 0.0])
    states = np.tile(np.array([0.0, 0.0, 0.3, 0.0]), (horizon + 1, 1))
    U0 = np.zeros((horizon, 1))
    ddp = PlanConfig().ddp
    running, terminal = wipm.costs()
    numpy_result = NumpyILQR(wipm.dynamics(), running, terminal, ddp)(
        x0, U0, params, refs_for(states, params)
    )
    peer = CrocoddylWIPM(wipm, params, horizon, ddp.mu_init).solve(
        x0, U0, params, states, 500, CROCODDYL_TH_STOP_CONVERGED
    )
    assert numpy_result.converged and peer.converged
    assert abs(peer.cost - numpy_result.cost) <= 1e-6 * abs(numpy_result.cost)


def test_qp_peers_agree_on_a_constrained_qp() -> None:
    """A small QP with active bounds (the recorded ones rarely touch a limit): every solver
    reaches the KKT-checked reference to 1e-6, also warm-started from a previous QP."""
    rng = np.random.default_rng(0)
    n, m = 6, 10
    A = rng.normal(size=(n, n))
    H = A @ A.T + 1e-3 * np.eye(n)
    C = rng.normal(size=(m, n))
    qps = []
    for k in range(3):
        g = rng.normal(size=n) * 10.0 * (k + 1)
        qps.append(RecordedQP(H, g, C, -np.ones(m), np.ones(m)))
    for solver in all_solvers():
        solver.start()
        for qp in qps:
            x_ref, kkt = reference_solution(qp)
            assert max(kkt.values()) <= 1e-8
            active = np.minimum(C @ x_ref - qp.lower, qp.upper - C @ x_ref) <= 1e-9
            assert active.any()
            assert solution_error(solver.solve(qp), x_ref) <= 1e-6, solver.name


def test_ddp_timing_script_runs() -> None:
    """``python -m benchmarks.speed.ddp_timing`` (the DDP alone, caller vs bare compiled call): it
    runs on the planar problem and its timed MPC steps do not retrace."""
    from benchmarks.speed.ddp_bench import krang_params
    from benchmarks.speed.ddp_timing import bench

    params, theta0 = krang_params()
    out = bench("planar", params, theta0, reps=1, mpc_steps=3)
    assert out["plan_iterations"] >= 1 and out["mpc_retraces"] == 0
    assert all(math.isfinite(v) and v > 0 for k, v in out.items() if k.endswith("_ms"))


def test_first_call_script_runs(capsys: pytest.CaptureFixture[str]) -> None:
    """``python -m benchmarks.speed.first_call`` plans, steps the MPC and prints both times."""
    from benchmarks.speed.first_call import main

    main([])
    out = capsys.readouterr().out
    assert out.startswith("first plan ") and out.rstrip().endswith("(planar)")


@pytest.mark.parametrize("planar", [True, False])
def test_ddp_parts_ablations_leave_out_only_what_they_say(planar: bool) -> None:
    """``benchmarks.speed.ddp_parts``' ablated backward passes: ``backward_quadratic``'s cost
    derivatives are the problem's where the penalty is inactive (it leaves out the penalty
    only), and ``backward_riccati``'s stand-in Jacobians have the shapes of the problem's."""
    import jax.numpy as jnp

    from benchmarks.speed.ddp_parts import _ablated_solvers

    params, _ = krang_params()
    wipm = mpc_problem(planar, MPCConfig(), a_max=1e6, theta_max=10.0)  # penalty never active
    quadratic, riccati = _ablated_solvers(wipm, MPCConfig().ddp)
    rng = np.random.default_rng(3)
    z = jnp.asarray(rng.normal(scale=0.1, size=wipm.n_state))
    w = jnp.asarray(rng.normal(scale=0.1, size=wipm.n_control))
    ref = (jnp.asarray(rng.normal(scale=0.1, size=wipm.n_state)), params)
    assert not bool(wipm.penalty(z, w, params)[1])
    exact = wipm.running_derivatives()(z, w, ref)
    for mine, theirs in zip(quadratic.running_derivatives(z, w, ref), exact, strict=True):
        np.testing.assert_allclose(mine, theirs, rtol=1e-14, atol=1e-14)
    real = wipm.dynamics_derivatives()(z, w, params)
    stand_in = riccati.dynamics_derivatives(z, w, params)
    assert [a.shape for a in stand_in] == [a.shape for a in real]
    # the stand-ins depend on the state and the input, so that XLA cannot fold the
    # recursion's products away
    moved = riccati.dynamics_derivatives(z + 0.1, w + 0.1, params)
    assert all(not np.array_equal(a, b) for a, b in zip(stand_in, moved, strict=True))
    with pytest.raises(ValueError, match="rate input"):
        _ablated_solvers(planning_problem(planar, PlanConfig(), 1.0, False), MPCConfig().ddp)


@pytest.mark.parametrize(("planar", "gradient"), [(True, False), (False, False), (False, True)])
def test_riccati_floor_compiled_recursion_is_the_ddps(planar: bool, gradient: bool) -> None:
    """``benchmarks.speed.riccati_floor``: the compiled recursion gives the DDP's backward pass
    (``DDPSolver._backward`` with the problem's own derivatives, with and without the gradient
    norm's adjoint recursion) on the same trajectory, and so does ``_backward`` over the stored
    derivatives; a ``Q_uu + mu I`` that is not positive definite at one step fails both, and a
    NaN gradient term makes the gradient norm NaN in both."""
    import dataclasses

    import jax.numpy as jnp

    from benchmarks.speed.riccati_floor import (
        as_result,
        compiled_recursion,
        problem_inputs,
        run_compiled,
        stored_backward,
    )
    from controllers.optimizer.ddp import rollout

    params, _ = krang_params()
    wipm = mpc_problem(planar, MPCConfig(), a_max=0.5, theta_max=0.1)
    solver = ddp_solver_for(wipm, dataclasses.replace(MPCConfig().ddp, gradient_norm=gradient))
    rng = np.random.default_rng(5)
    steps, n, m = 30, wipm.n_state, wipm.n_control
    U = jnp.asarray(rng.normal(scale=2.0, size=(steps, m)))
    X = rollout(wipm.dynamics(), jnp.asarray(rng.normal(scale=0.05, size=n)), U, params)
    refs = refs_for(rng.normal(scale=0.1, size=(steps + 1, n)), params)
    inputs = problem_inputs(solver, X, U, params, refs)
    mu = 1e-3
    truth = as_result(solver._backward(X, U, params, refs, jnp.asarray(mu)))
    assert truth.ok
    assert np.isfinite(truth.grad_norm) == gradient
    for result in (
        run_compiled(inputs, mu, gradient),
        as_result(stored_backward(inputs, gradient).call(mu)),
    ):
        assert result.ok
        scale = np.abs(truth.K).max()
        np.testing.assert_allclose(result.K, truth.K, rtol=0, atol=1e-10 * scale)
        np.testing.assert_allclose(result.k, truth.k, rtol=0, atol=1e-10 * np.abs(truth.k).max())
        assert result.dv1 == pytest.approx(truth.dv1, rel=1e-10)
        assert result.dv2 == pytest.approx(truth.dv2, rel=1e-10)
        if gradient:
            assert result.grad_norm == pytest.approx(truth.grad_norm, rel=1e-10)
        else:
            assert np.isnan(result.grad_norm)
    # Q_uu not positive definite at one step (the last, which the recursion meets first): the
    # pass fails; with the gradient norm, a NaN in one gradient term makes it NaN in both
    broken = inputs._replace(luu=inputs.luu.copy())
    broken.luu[-1] = -1e6 * np.eye(m)
    nan_grad = inputs._replace(lu=inputs.lu.copy())
    nan_grad.lu[steps // 2, 0] = np.nan
    for case in (broken, nan_grad):
        compiled = run_compiled(case, mu, gradient)
        xla = as_result(stored_backward(case, gradient).call(mu))
        assert not compiled.ok and not xla.ok
        if case is nan_grad:
            assert np.isnan(compiled.grad_norm) and np.isnan(xla.grad_norm)
    with pytest.raises(ValueError, match="m >= 1"):
        compiled_recursion(2, 0)


@pytest.mark.parametrize("planar", [True, False])
def test_stage_codegen_equals_jax_on_both_sides_of_the_penalty(planar: bool) -> None:
    """``benchmarks.speed.stage_codegen``: the scalar code generated from the jaxpr of the
    MPC problem's stage (dynamics, its Jacobians, the running cost's derivatives) gives JAX's
    values on random states, where the acceleration penalty is inactive and where it is active
    (its ``cond``'s two branches); a primitive it has no form for is refused by name."""
    import jax
    import jax.numpy as jnp

    from benchmarks.speed.stage_codegen import stage_function, stage_rows
    from controllers.optimizer.scalar_codegen import scalar_function

    params, _ = krang_params()
    wipm = mpc_problem(planar, MPCConfig(), a_max=0.5, theta_max=0.1)
    stage, inputs, outputs = stage_function(wipm, params)
    n, m = wipm.n_state, wipm.n_control
    dynamics = wipm.dynamics()
    jacobians, derivatives = wipm.dynamics_derivatives(), wipm.running_derivatives()
    rng = np.random.default_rng(11)
    active = []
    for scale in (0.01, 30.0) * 4:  # small and large torques: the penalty off and on
        x = rng.normal(scale=0.1, size=n)
        u = rng.normal(scale=scale, size=m)
        s_ref = rng.normal(scale=0.1, size=n)
        z = stage_rows(x[None], u[None], s_ref[None], params)[0]
        assert z.shape == (inputs,)
        out = np.empty(outputs)
        stage(z, out)
        xj, uj, sj = jnp.asarray(x), jnp.asarray(u), jnp.asarray(s_ref)
        truth = jax.tree.leaves(
            (dynamics(xj, uj, params), jacobians(xj, uj, params), derivatives(xj, uj, (sj, params)))
        )
        expected = np.concatenate([np.ravel(np.asarray(a)) for a in truth])
        np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
        active.append(bool(wipm.penalty(xj, uj, params)[1]))
    assert any(active) and not all(active)
    # a product and a sum (dot_general, reduce_sum) written out, and a primitive refused
    product, _, _ = scalar_function(
        lambda a, b: (a @ b, jnp.sum(a, axis=0)), jnp.ones((2, 3)), jnp.ones(3)
    )
    a, b = rng.normal(size=(2, 3)), rng.normal(size=3)
    result = np.empty(5)
    product(np.concatenate([a.ravel(), b]), result)
    np.testing.assert_allclose(result, np.concatenate([a @ b, a.sum(axis=0)]), rtol=1e-14)
    with pytest.raises(NotImplementedError, match="'sort'"):
        scalar_function(jnp.sort, jnp.ones(3))


@pytest.mark.parametrize("problem", ["planar", "3d"])
def test_mpc_backends_benchmark_times_equal_solves(problem: str) -> None:
    """``benchmarks.speed.mpc_backends``: both backends timed on the same window, their
    predictions equal to round-off (what the table's last columns report)."""
    from benchmarks.speed.mpc_backends import measure

    ((name, row),) = measure(rounds=1, indices=(100,), problems=(problem,)).items()
    assert name == f"{problem} 100"
    assert row["jax_us"] > 0 and row["numba_us"] > 0 and row["unit_us"] > 0
    assert row["max_dU"] < 1e-9 and row["max_dX"] < 1e-9
