"""``wip-bench solvers``: solver timings of the JAX DDP against a plain NumPy iLQR (issue 4).

Measured in one run, in one process, on this machine, for two problems:

* planar: the planar 4-state WIPM with Krang's ``lambda(q)`` at its initial pose (``Krang-v0``,
  ``reset(seed=0)``, no reset noise), from ``[theta0, 0, 0, 0]`` to ``x = 2 m``;
* 3d: the 3-D 8-state WIPM with the same parameters, from ``[0, 0, theta0, 0, 0, 0, 0, 0]`` to
  ``(X0, Y0) = (2, 1)``.

For each problem and each solver (``ours``: ``controllers.ddp`` through
``controllers.planning`` / ``controllers.mpc``; ``numpy_ilqr``: :mod:`benchmarks.numpy_ilqr`):

* ``compile_s``: first call minus a steady-state call of the offline plan solve (JAX tracing
  and XLA compilation; for the NumPy peer, the compilation of its jitted derivative helpers);
* ``plan_ms``: the offline plan solve (``N = 2000``, the planner's DDP settings: iLQR, up to
  100 iterations, tolerance 1e-9), median over repetitions, with ``plan_iterations``,
  ``plan_cost`` and ``plan_converged``;
* ``iter_ms``: ``plan_ms / plan_iterations`` (the initial backward pass included);
* ``mpc_step_ms``: ``median`` and ``p99`` of the MPC step (``N = 100``, warm start from the
  previous solution shifted, the default budget of 2 iterations) over consecutive steps along
  the plan from the plan's states. Ours is the whole ``ModelPredictiveController.step`` (the
  references, the solve, the acceptance test and the shift); the peer does the same work.
  ``mpc_compile_s`` is its first step minus the median.

``ratios`` are ``ours / numpy_ilqr`` (below 1: ours is faster). ``cost_rel_diff`` compares the
two converged offline plans' costs (they should agree to 1e-6 relative).

    wip-bench solvers [--quick] [--json PATH]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import jax
import numpy as np

import wip_gym  # noqa: F401  (registers the environments)
from benchmarks.numpy_ilqr import NumpyILQR
from controllers.ddp import DDPConfig
from controllers.mpc import ModelPredictiveController, MPCConfig, mpc_problem
from controllers.planning import PlanConfig, plan_to_goal, planning_problem
from controllers.policy import make_robot
from controllers.wipm import WIPMParams, params_from_lambda
from controllers.wipm_problem import ddp_solver_for, refs_for

ENV_ID = "wip_gym/Krang-v0"
PLAN_TARGET_MS = 50.0
MPC_TARGET_MS = 1.0
COST_TOLERANCE = 1e-6
PROBLEMS = ("planar", "3d")
GOALS = {"planar": (2.0, 0.0), "3d": (2.0, 1.0)}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``solvers`` subcommand's flags."""
    parser.add_argument(
        "--quick", action="store_true", help="fewer repetitions (a smoke test, not figures)"
    )
    parser.add_argument("--json", type=Path, default=None, help="write the results as JSON")
    parser.add_argument(
        "--mpc-steps", type=int, default=None, help="MPC steps timed (default 200, quick 20)"
    )


def krang_params() -> tuple[WIPMParams, float]:
    """Krang's ``lambda(q)`` at its initial pose as WIPM parameters, and its pitch ``theta0``."""
    env = gym.make(ENV_ID, reset_noise_scale=0.0)
    try:
        obs, _ = env.reset(seed=0)
        robot = make_robot(env, "nominal")
        robot.update(obs["qpos"], obs["qvel"])
        return params_from_lambda(robot.wipm_parameters()), float(robot.theta)
    finally:
        env.close()


def _initial_state(problem: str, theta0: float) -> np.ndarray:
    if problem == "planar":
        return np.array([theta0, 0.0, 0.0, 0.0])
    return np.array([0.0, 0.0, theta0, 0.0, 0.0, 0.0, 0.0, 0.0])


def _goal_state(problem: str, state: np.ndarray, goal_xy: np.ndarray) -> np.ndarray:
    """The planner's goal state (``plan_to_goal``'s: at rest, upright; 3-D heading free, so
    facing the goal's bearing from the start)."""
    if problem == "planar":
        return np.array([0.0, 0.0, goal_xy[0], 0.0])
    delta = goal_xy - state[6:8]
    heading = state[1] + np.angle(np.exp(1j * (np.arctan2(delta[1], delta[0]) - state[1])))
    return np.array([0.0, heading, 0.0, 0.0, 0.0, 0.0, *goal_xy])


def _timed(fn: Callable[[], Any]) -> tuple[float, Any]:
    """Wall time (s) of ``fn()`` and its result (JAX results are waited for)."""
    start = time.perf_counter()
    out = fn()
    jax.block_until_ready(out)
    return time.perf_counter() - start, out


def _p99(values: list[float]) -> float:
    return float(np.percentile(np.asarray(values), 99))


def _plan_timings(solve: Callable[[], Any], repetitions: int) -> tuple[float, float, Any]:
    """``compile_s`` (first call minus the median), median plan seconds, last result."""
    first, result = _timed(solve)
    times = []
    for _ in range(repetitions):
        seconds, result = _timed(solve)
        times.append(seconds)
    median = statistics.median(times)
    return max(first - median, 0.0), median, result


def _mpc_timings(
    step: Callable[[int], Any], warmup: Callable[[], None], steps: int
) -> tuple[float, list[float]]:
    """``mpc_compile_s`` (the throwaway first step minus the median) and the step times (s)."""
    first, _ = _timed(warmup)
    times = [_timed(lambda i=i: step(i))[0] for i in range(steps)]
    return max(first - statistics.median(times), 0.0), times


class _NumpyMPC:
    """The NumPy peer's MPC step: the same references, warm start and shift as
    ``ModelPredictiveController.step`` (acceptance test included), its solver the peer's."""

    def __init__(self, plan: Any, solver: NumpyILQR, horizon: int) -> None:
        self.plan = plan
        self.solver = solver
        self.horizon = horizon
        self._controls: np.ndarray | None = None

    def step(self, index: int, state: np.ndarray, params: WIPMParams) -> np.ndarray:
        refs = refs_for(self.plan.window(index, self.horizon + 1), params)
        warm = (
            self._controls
            if self._controls is not None
            else self.plan.control_window(index, self.horizon)
        )
        result = self.solver(state, warm, params, refs)
        U = result.U
        accepted = bool(
            np.all(np.isfinite(U))
            and np.isfinite(result.cost)
            and result.cost <= result.initial_cost * (1 + 1e-12) + 1e-12
        )
        if not accepted:
            U = warm
        self._controls = np.vstack([U[1:], self.plan.control_window(index + self.horizon, 1)])
        return U[0].copy()


def bench_problem(
    problem: str,
    params: WIPMParams,
    theta0: float,
    *,
    plan_reps: int,
    numpy_reps: int,
    mpc_steps: int,
    plan_horizon_s: float = 20.0,
) -> dict[str, Any]:
    """Both solvers on one problem (see the module docstring for the keys)."""
    planar = problem == "planar"
    config = PlanConfig(horizon_s=plan_horizon_s)
    state = _initial_state(problem, theta0)
    goal_xy = np.asarray(GOALS[problem])
    a_max = config.acceleration_bound(None, float(params.gravity))
    wipm = planning_problem(planar, config, a_max, heading_given=False)

    steps = config.steps
    m = wipm.n_control
    goal = _goal_state(problem, state, goal_xy)
    z0 = np.concatenate([state, np.zeros(m)])
    U0 = np.zeros((steps, m))
    refs = refs_for(np.tile(goal, (steps + 1, 1)), params)

    # ours: the planner's own (cached) solver, first used here, so the first call compiles
    ours = ddp_solver_for(wipm, config.ddp)
    compile_s, plan_s, result = _plan_timings(lambda: ours(z0, U0, params, refs), plan_reps)
    ours_iters = int(result.iterations)
    ours_out: dict[str, Any] = {
        "compile_s": compile_s,
        "plan_ms": 1e3 * plan_s,
        "plan_iterations": ours_iters,
        "iter_ms": 1e3 * plan_s / max(ours_iters, 1),
        "plan_cost": float(result.cost),
        "plan_converged": bool(result.converged),
    }

    running, terminal = wipm.costs()
    peer = NumpyILQR(wipm.dynamics(), running, terminal, config.ddp)
    compile_np, plan_np, result_np = _plan_timings(lambda: peer(z0, U0, params, refs), numpy_reps)
    numpy_out: dict[str, Any] = {
        "compile_s": compile_np,
        "plan_ms": 1e3 * plan_np,
        "plan_iterations": result_np.iterations,
        "iter_ms": 1e3 * plan_np / max(result_np.iterations, 1),
        "plan_cost": result_np.cost,
        "plan_converged": result_np.converged,
    }

    # the plan itself (the same cached solver: no compilation), to run the MPC along
    plan = plan_to_goal(state, params, goal_xy, planar=planar, config=config)
    if not np.allclose(plan.goal_state, goal) or abs(
        plan.cost - ours_out["plan_cost"]
    ) > 1e-9 * abs(plan.cost):
        raise RuntimeError("the benchmark's plan problem differs from plan_to_goal's")

    # MPC along the plan, from the plan's states, warm-started step to step
    mpc_config = MPCConfig()
    horizon = mpc_config.steps
    warm_index = steps // 2  # the throwaway compile step, away from the timed window

    def fresh() -> ModelPredictiveController:
        return ModelPredictiveController(plan, mpc_config)

    throwaway = fresh()
    timed = fresh()
    mpc_compile, mpc_times = _mpc_timings(
        lambda i: timed.step(i, plan.states[i], params).control,
        lambda: throwaway.step(warm_index, plan.states[warm_index], params).control,
        mpc_steps,
    )
    ours_out["mpc_compile_s"] = mpc_compile
    ours_out["mpc_step_ms"] = {
        "median": 1e3 * statistics.median(mpc_times),
        "p99": 1e3 * _p99(mpc_times),
        "steps": mpc_steps,
    }

    mpc_wipm = mpc_problem(planar, mpc_config, plan.a_max, plan.theta_max)
    mpc_running, mpc_terminal = mpc_wipm.costs()
    mpc_ddp = DDPConfig(**{**mpc_config.ddp.__dict__, "max_iterations": mpc_config.iterations})
    mpc_peer = NumpyILQR(mpc_wipm.dynamics(), mpc_running, mpc_terminal, mpc_ddp)
    throwaway_np = _NumpyMPC(plan, mpc_peer, horizon)
    timed_np = _NumpyMPC(plan, mpc_peer, horizon)
    mpc_compile_np, mpc_times_np = _mpc_timings(
        lambda i: timed_np.step(i, plan.states[i], params),
        lambda: throwaway_np.step(warm_index, plan.states[warm_index], params),
        mpc_steps,
    )
    numpy_out["mpc_compile_s"] = mpc_compile_np
    numpy_out["mpc_step_ms"] = {
        "median": 1e3 * statistics.median(mpc_times_np),
        "p99": 1e3 * _p99(mpc_times_np),
        "steps": mpc_steps,
    }

    rel = abs(ours_out["plan_cost"] - numpy_out["plan_cost"]) / max(
        abs(ours_out["plan_cost"]), 1e-300
    )
    return {
        "ours": ours_out,
        "numpy_ilqr": numpy_out,
        "plan_steps": steps,
        "mpc_horizon": horizon,
        "mpc_iterations": mpc_config.iterations,
        "cost_rel_diff": rel,
        "costs_agree": bool(rel <= COST_TOLERANCE),
    }


def _ratio(ours: float, peer: float) -> float | None:
    return ours / peer if peer > 0 else None


def _ratios(entry: dict[str, Any]) -> dict[str, float | None]:
    ours, peer = entry["ours"], entry["numpy_ilqr"]
    return {
        "compile": _ratio(ours["compile_s"], peer["compile_s"]),
        "plan": _ratio(ours["plan_ms"], peer["plan_ms"]),
        "iter": _ratio(ours["iter_ms"], peer["iter_ms"]),
        "mpc_step_median": _ratio(ours["mpc_step_ms"]["median"], peer["mpc_step_ms"]["median"]),
        "mpc_step_p99": _ratio(ours["mpc_step_ms"]["p99"], peer["mpc_step_ms"]["p99"]),
    }


def _fmt(value: float | None, spec: str) -> str:
    return "n/a" if value is None else format(value, spec)


def run_benchmark(quick: bool = False, mpc_steps: int | None = None) -> dict[str, Any]:
    """All measurements as one JSON-ready dictionary."""
    if mpc_steps is None:
        mpc_steps = 20 if quick else 200
    if mpc_steps < 1:
        raise ValueError(f"--mpc-steps must be >= 1, got {mpc_steps}")
    plan_reps, numpy_reps = (2, 1) if quick else (10, 3)
    plan_horizon_s = 10.0 if quick else 20.0  # quick: N = 1000
    params, theta0 = krang_params()
    out: dict[str, Any] = {
        "command": "wip-bench solvers" + (" --quick" if quick else ""),
        "quick": quick,
        "machine": {
            "platform": platform.platform(),
            "processor": platform.processor() or platform.machine(),
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "jax": jax.__version__,
            "numpy": np.__version__,
            "load_average_1min_at_start": os.getloadavg()[0],
        },
        "theta0": theta0,
        "plan_horizon_s": plan_horizon_s,
        "repetitions": {"plan_ours": plan_reps, "plan_numpy": numpy_reps, "mpc": mpc_steps},
    }
    for problem in PROBLEMS:
        out[problem] = bench_problem(
            problem,
            params,
            theta0,
            plan_reps=plan_reps,
            numpy_reps=numpy_reps,
            mpc_steps=mpc_steps,
            plan_horizon_s=plan_horizon_s,
        )
    out["ratios"] = {"definition": "ours / numpy_ilqr"} | {p: _ratios(out[p]) for p in PROBLEMS}
    out["targets"] = {
        "plan_under_50ms": {p: out[p]["ours"]["plan_ms"] < PLAN_TARGET_MS for p in PROBLEMS},
        "mpc_median_under_1ms": {
            p: out[p]["ours"]["mpc_step_ms"]["median"] < MPC_TARGET_MS for p in PROBLEMS
        },
    }
    return out


def format_table(results: dict[str, Any]) -> str:
    """A plain-text table of the results (Markdown-compatible)."""
    header = (
        "| problem | solver | compile (s) | plan (ms) | iters | per iter (ms) | "
        "MPC median (ms) | MPC p99 (ms) |"
    )
    lines = [f"$ {results['command']}", "", header, "|" + "---|" * 8]
    for problem in PROBLEMS:
        entry = results[problem]
        for name in ("ours", "numpy_ilqr"):
            r = entry[name]
            lines.append(
                f"| {problem} | {name} | {r['compile_s']:.2f} | {r['plan_ms']:.1f} | "
                f"{r['plan_iterations']} | {r['iter_ms']:.2f} | "
                f"{r['mpc_step_ms']['median']:.3f} | {r['mpc_step_ms']['p99']:.3f} |"
            )
        q = results["ratios"][problem]
        lines.append(
            f"| {problem} | ratio ours/numpy | {_fmt(q['compile'], '.2f')} | "
            f"{_fmt(q['plan'], '.3f')} | | {_fmt(q['iter'], '.3f')} | "
            f"{_fmt(q['mpc_step_median'], '.3f')} | {_fmt(q['mpc_step_p99'], '.3f')} |"
        )
    lines.append("")
    for problem in PROBLEMS:
        entry = results[problem]
        lines.append(
            f"{problem}: plan cost ours {entry['ours']['plan_cost']:.10g}, numpy "
            f"{entry['numpy_ilqr']['plan_cost']:.10g} (relative difference "
            f"{entry['cost_rel_diff']:.1e}: {'agree' if entry['costs_agree'] else 'DISAGREE'} "
            f"to {COST_TOLERANCE:g}); N = {entry['plan_steps']}, MPC N = {entry['mpc_horizon']}, "
            f"{entry['mpc_iterations']} iterations, {entry['ours']['mpc_step_ms']['steps']} steps"
        )
    met = []
    labels = {
        "plan_under_50ms": "offline plan < 50 ms",
        "mpc_median_under_1ms": "MPC step median < 1 ms",
    }
    for key, label in labels.items():
        for problem, ok in results["targets"][key].items():
            met.append(f"{label} ({problem}): {'met' if ok else 'NOT met'}")
    lines.append("Targets: " + "; ".join(met))
    return "\n".join(lines)


def run(args: argparse.Namespace) -> None:
    """The ``solvers`` subcommand."""
    results = run_benchmark(quick=args.quick, mpc_steps=args.mpc_steps)
    print(format_table(results))
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2))
        print(f"wrote {args.json}")
