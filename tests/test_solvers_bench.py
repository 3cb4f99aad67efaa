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
    # the figures derived in the run are what they are computed from: each ratio a peer's
    # median over ours, each target its figure against its limit
    for p in PROBLEMS:
        for kind, table in (("plan", "ddp_plan_ms"), ("mpc", "mpc_step_ms")):
            ours = results[table][p]["ours"]["median"]
            for peer, label in (("crocoddyl", "crocoddyl"), ("numpy_ilqr", "numpy")):
                assert results["ratios"][f"{label}_{kind}_{p}"] == pytest.approx(
                    results[table][p][peer]["median"] / ours, rel=1e-12
                ), (label, kind, p)
    for env in QP_ENVS:
        times = results["qp_solve_us"][env]
        for s in QP_SOLVERS[2:]:
            peer = times[s]["median"]
            assert results["ratios"][f"qp_{s}_{env}"] == pytest.approx(
                peer / times["proxqp"]["median"], rel=1e-12
            )
            assert results["ratios_controller_path"][f"qp_{s}_{env}"] == pytest.approx(
                peer / times["proxqp_shortcut"]["median"], rel=1e-12
            )
    for name, target in results["targets"].items():
        below = not name.endswith("_at_least_10x")
        met = target["figure"] <= target["limit"] if below else target["figure"] >= target["limit"]
        assert target["met"] is met, name
    for p in PROBLEMS:
        assert (
            results["targets"][f"plan_under_10ms_{p}"]["figure"]
            == (results["ddp_plan_ms"][p]["ours"]["median"])
        )
        assert (
            results["targets"][f"crocoddyl_mpc_{p}_at_least_10x"]["figure"]
            == (results["ratios"][f"crocoddyl_mpc_{p}"])
        )
    krang = results["qp_solve_us"]["krang"]
    fastest_peer = min(krang[s]["median"] for s in QP_SOLVERS[2:])  # every peer agrees (below)
    assert results["targets"]["qp_krang_within_2x_fastest_peer"]["figure"] == pytest.approx(
        krang["proxqp"]["median"] / fastest_peer, rel=1e-12
    )
    units_3d = results["mpc_step_units"]["3d"]
    assert results["targets"]["mpc_step_under_15_units_3d"]["figure"] == units_3d["median"]
    assert results["targets"]["mpc_step_p99_under_2x_median_3d"]["figure"] == pytest.approx(
        units_3d["p99"] / units_3d["median"], rel=1e-12
    )
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
