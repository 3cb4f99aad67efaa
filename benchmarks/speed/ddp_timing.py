"""Timing of the JAX DDP alone: the offline plan (N = 2000) and the MPC step, as the
caller sees them and as a bare jitted call, for the planar and the 3-D WIPM.

``python -m benchmarks.speed.ddp_timing [--reps R] [--mpc-steps S]`` prints medians (ms). The
problems are those of ``wip-bench solvers`` (Krang's ``lambda(q)``, goals (2, 0) and (2, 1)).
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from typing import Any

import jax
import numpy as np

from benchmarks.speed.ddp_bench import GOALS, krang_params
from controllers.high_level.mpc import ModelPredictiveController, MPCConfig, pack_inputs
from controllers.high_level.planning import PlanConfig, plan_to_goal, planning_problem
from controllers.simplified.wipm import WIPMParams
from controllers.simplified.wipm_problem import ddp_solver_for, refs_for


def _time(fn: Callable[[], Any]) -> float:
    start = time.perf_counter()
    jax.block_until_ready(fn())
    return time.perf_counter() - start


def _median_ms(times: list[float]) -> float:
    return 1e3 * statistics.median(times)


def bench(problem: str, params: WIPMParams, theta0: float, reps: int, mpc_steps: int) -> dict:
    planar = problem == "planar"
    config = PlanConfig()
    state = (
        np.array([theta0, 0.0, 0.0, 0.0])
        if planar
        else np.array([0.0, 0.0, theta0, 0.0, 0.0, 0.0, 0.0, 0.0])
    )
    goal_xy = np.asarray(GOALS[problem])
    plan = plan_to_goal(state, params, goal_xy, planar=planar, config=config)  # compiles
    wipm = planning_problem(planar, config, config.acceleration_bound(None), False)
    solver = ddp_solver_for(wipm, config.ddp)
    m = wipm.n_control
    z0 = np.concatenate([state, np.zeros(m)])
    U0 = np.zeros((config.steps, m))
    refs = refs_for(np.tile(plan.goal_state, (config.steps + 1, 1)), params)
    plan_times = [_time(lambda: solver(z0, U0, params, refs)) for _ in range(reps)]
    iterations = int(solver(z0, U0, params, refs).iterations)

    jax_mpc = MPCConfig(backend="jax")  # the JAX step (the numba backend: mpc_backends)
    mpc = ModelPredictiveController(plan, jax_mpc)
    mpc.step(500, plan.states[500], params)  # compiles
    traces = mpc.compiled.trace_count  # the compiled step is shared process-wide
    mpc = ModelPredictiveController(plan, jax_mpc)
    step_times = [
        _time(lambda i=i: mpc.step(i, plan.states[i], params).control) for i in range(mpc_steps)
    ]
    # the bare compiled solve on device arrays, same inputs as the MPC's last call
    refs_mpc = jax.device_put(refs_for(plan.window(0, mpc.horizon + 1), params))
    warm = jax.device_put(plan.control_window(0, mpc.horizon))
    x0 = jax.device_put(plan.states[0])
    p = jax.device_put(params)
    bare = [_time(lambda: mpc.solver.jitted(x0, warm, p, refs_mpc)) for _ in range(mpc_steps)]
    host = jax.device_put(pack_inputs(0, False, plan.states[0], params))
    step_args = (host, warm, mpc._plan_states, mpc._plan_controls)
    step_bare = [_time(lambda: mpc.compiled.jitted(*step_args)) for _ in range(mpc_steps)]
    return {
        "plan_ms": _median_ms(plan_times),
        "plan_iterations": iterations,
        "iter_ms": _median_ms(plan_times) / max(iterations, 1),
        "mpc_step_ms": _median_ms(step_times),
        "mpc_step_p90_ms": 1e3 * float(np.percentile(step_times, 90)),
        "mpc_bare_solver_ms": _median_ms(bare),
        "mpc_bare_step_ms": _median_ms(step_bare),
        "mpc_retraces": mpc.compiled.trace_count - traces,  # during the timed steps: 0
    }


def main() -> None:
    from controllers.optimizer import jax_setup

    jax_setup.configure()  # the solvers' JAX settings, before JAX starts
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--reps", type=int, default=10)
    parser.add_argument("--mpc-steps", type=int, default=200)
    args = parser.parse_args()
    params, theta0 = krang_params()
    for problem in ("planar", "3d"):
        start = time.perf_counter()
        out = bench(problem, params, theta0, args.reps, args.mpc_steps)
        setup = time.perf_counter() - start
        cells = "  ".join(
            f"{k}={v:.3f}" if isinstance(v, float) else f"{k}={v}" for k, v in out.items()
        )
        print(f"{problem:6s} {cells}  (total {setup:.1f} s)", flush=True)


if __name__ == "__main__":
    main()
