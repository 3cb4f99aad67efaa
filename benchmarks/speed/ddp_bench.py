"""The DDP half of ``wip-bench solvers``: our DDP (the plan: the JAX DDP; the MPC step: its
default backend, numba, ``MPCConfig.backend``) against crocoddyl and a NumPy iLQR on the WIPM.

Two problems, both from Krang's ``lambda(q)`` at its initial pose (``Krang-v0``,
``reset(seed=0)``, no reset noise):

* planar: the planar 4-state WIPM (paper eq. ``WIPdyn``, docs/ERRATA.md §1) from
  ``[theta0, 0, 0, 0]`` to ``x = 2 m``;
* 3d: the 3-D 8-state WIPM from ``[0, 0, theta0, 0, 0, 0, 0, 0]`` to ``(X0, Y0) = (2, 1)``.

Three solvers of the same discrete problem (``controllers.simplified.wipm_problem``: explicit
Euler, the running cost with its ``dt``, the penalties, the terminal cost; eq. (1) of
``controllers.optimizer.ddp``):

* ``ours``: ``controllers.optimizer.ddp`` through ``controllers.high_level.planning`` /
  ``controllers.high_level.mpc``;
* ``crocoddyl``: crocoddyl's ``SolverDDP`` with the problem as a Python action model
  (:mod:`benchmarks.speed.crocoddyl_wipm`);
* ``numpy_ilqr``: :mod:`benchmarks.speed.numpy_ilqr` (our algorithm, step for step, in NumPy loops).

Measured per problem and solver:

* the optimum: the offline plan (``N = 2000``; the planner's settings: iLQR, up to 100
  iterations, tolerance 1e-9; crocoddyl: its own stopping test ``sum ||Q_u||^2 < 1e-9``, up to
  :data:`PEER_MAX_ITERATIONS`) and one MPC step run to convergence from the same shifted warm
  start (the previous MPC step's controls, shifted; ours and the NumPy iLQR with the planner's
  tolerance, crocoddyl to :data:`CROCODDYL_TH_STOP_CONVERGED`): the costs must agree to
  :data:`COST_TOLERANCE` relative, else ``RuntimeError`` and no figures. The timed plans are
  these converged solves; the converged MPC step runs after the timed MPC steps, so that each
  solver's first MPC call (its compilation) is the timing's throwaway step;
* ``plan_ms``: wall time of the offline plan solve (median, p99 over repetitions), and
  ``iter_ms`` the same divided by that solve's iterations;
* ``compile_s``: first plan call minus the median (JAX tracing and compilation: our solver, the
  peers' jitted per-node or per-trajectory helpers), reported apart from every timing;
* ``mpc_step_ms``: the MPC step (``N = 100``, warm start from the previous solution shifted,
  the default budget of 2 iterations, no tolerance stop) over consecutive plan indices from the
  plan's states. Ours is the whole ``ModelPredictiveController.step`` (references, solve,
  acceptance test, shift); each peer does the same work around its own solver.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, Protocol

import gymnasium as gym
import jax
import numpy as np
from tqdm import tqdm

import wip_gym  # noqa: F401  (registers the environments)
from benchmarks.speed.crocoddyl_wipm import CrocoddylWIPM
from benchmarks.speed.numpy_ilqr import NumpyILQR
from benchmarks.speed.yardstick import ReferenceStep, times_between_bursts
from controllers.high_level.mpc import ModelPredictiveController, MPCConfig, mpc_problem
from controllers.high_level.planning import Plan, PlanConfig, plan_to_goal, planning_problem
from controllers.policy import make_robot
from controllers.simplified.wipm import WIPMParams, params_from_lambda
from controllers.simplified.wipm_problem import ddp_solver_for, refs_for

ENV_ID = "wip_gym/Krang-v0"
PROBLEMS = ("planar", "3d")
SOLVERS = ("ours", "crocoddyl", "numpy_ilqr")
GOALS = {"planar": (2.0, 0.0), "3d": (2.0, 1.0)}
COST_TOLERANCE = 1e-6
PEER_MAX_ITERATIONS = 500
CROCODDYL_TH_STOP = 1e-9  # crocoddyl's default stopping threshold on sum ||Q_u||^2
# Its test is absolute: at the MPC check's costs, O(1e-4), 1e-9 can stop before the first step
# (measured: 2.9e-7 relative from the optimum, planar, index 500), so the converged MPC step is
# run to 1e-15 (a few more iterations; 1e-12 to 1e-24 all land within 1e-12 of our cost).
CROCODDYL_TH_STOP_CONVERGED = 1e-15
# the MPC's fixed budget: no tolerance stop (ours: tolerance 0; crocoddyl wants th_stop > 0)
CROCODDYL_NO_STOP = float(np.finfo(np.float64).tiny)


@dataclass(frozen=True)
class DDPBenchConfig:
    """Sizes of one run.

    Attributes:
        plan_horizon_s: offline plan horizon (20 s at 10 ms: ``N = 2000``).
        plan_reps_ours, plan_reps_peers: timed plan repetitions after the first (compile) call.
        mpc_steps: timed MPC steps per solver and problem.
    """

    plan_horizon_s: float = 20.0
    plan_reps_ours: int = 5
    plan_reps_peers: int = 2
    mpc_steps: int = 200


class _StepResult(Protocol):
    U: Any
    cost: Any
    initial_cost: Any


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


def initial_state(problem: str, theta0: float) -> np.ndarray:
    if problem == "planar":
        return np.array([theta0, 0.0, 0.0, 0.0])
    return np.array([0.0, 0.0, theta0, 0.0, 0.0, 0.0, 0.0, 0.0])


def goal_state(problem: str, state: np.ndarray, goal_xy: np.ndarray) -> np.ndarray:
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


def stats_ms(seconds: list[float]) -> dict[str, float]:
    """``median`` and ``p99`` in milliseconds."""
    values = np.asarray(seconds) * 1e3
    return {"median": float(np.median(values)), "p99": float(np.percentile(values, 99))}


def relative_difference(a: float, b: float) -> float:
    return abs(a - b) / max(abs(a), abs(b), 1e-300)


def _plan_runs(
    solve: Callable[[], Any], repetitions: int, label: str
) -> tuple[float, list[float], list[int], Any]:
    """``compile_s`` (first call minus the median), the timed runs' seconds and iterations, and
    the last result."""
    first, result = _timed(solve)
    times: list[float] = []
    iterations: list[int] = []
    for _ in tqdm(range(repetitions), desc=label, leave=False, disable=None):
        seconds, result = _timed(solve)
        times.append(seconds)
        iterations.append(int(result.iterations))
    return max(first - statistics.median(times), 0.0), times, iterations, result


def _plan_entry(
    compile_s: float, times: list[float], iterations: list[int], result: Any
) -> dict[str, Any]:
    return {
        "compile_s": compile_s,
        "plan_ms": stats_ms(times),
        "plan_iterations": iterations[-1],
        "iter_ms": stats_ms([t / max(i, 1) for t, i in zip(times, iterations, strict=True)]),
        "plan_cost": float(result.cost),
        "plan_converged": bool(result.converged),
        "plan_repetitions": len(times),
    }


class _PeerMPC:
    """A peer's MPC step: the same references, warm start, acceptance test and shift as
    ``ModelPredictiveController.step``, its solver the peer's ``solve(state, warm, refs)``."""

    def __init__(self, plan: Plan, horizon: int, solve: Callable[..., _StepResult]) -> None:
        self.plan = plan
        self.horizon = horizon
        self.solve = solve
        self.controls: np.ndarray | None = None

    def step(self, index: int, state: np.ndarray, params: WIPMParams) -> np.ndarray:
        states = self.plan.window(index, self.horizon + 1)
        warm = (
            self.controls
            if self.controls is not None
            else self.plan.control_window(index, self.horizon)
        )
        result = self.solve(state, warm, params, states)
        U = np.asarray(result.U)
        cost, initial = float(result.cost), float(result.initial_cost)
        accepted = bool(
            np.all(np.isfinite(U)) and np.isfinite(cost) and cost <= initial * (1 + 1e-12) + 1e-12
        )
        if not accepted:
            U = warm
        self.controls = np.vstack([U[1:], self.plan.control_window(index + self.horizon, 1)])
        return U[0].copy()


REFERENCE_SAMPLES: list[float] = []  # the unit's samples taken between the timed MPC steps
REFERENCE_EVERY = 50  # MPC steps between two bursts of the unit's reference step


def _mpc_times(
    step: Callable[[int], Any], warmup: Callable[[], Any], steps: int, label: str
) -> tuple[float, list[float]]:
    """``mpc_compile_s`` (a throwaway first step minus the median) and the step times (s).
    After every ``REFERENCE_EVERY`` steps a burst of reference steps (``ReferenceStep.burst``:
    warm, as the unit is defined) is timed too, into ``REFERENCE_SAMPLES``, so that the unit
    sees the same machine load as the steps; the step after a burst, which the burst slowed, is
    run but not counted."""
    first, _ = _timed(warmup)
    times = times_between_bursts(
        lambda i: _timed(lambda: step(i))[0],
        tqdm(range(steps), desc=label, leave=False, disable=None),
        steps,
        REFERENCE_EVERY,
        ReferenceStep(),
        REFERENCE_SAMPLES,
    )
    return max(first - statistics.median(times), 0.0), times


def bench_problem(
    problem: str, params: WIPMParams, theta0: float, config: DDPBenchConfig
) -> dict[str, Any]:
    """The three solvers on one problem: optimum checks, then timings (module docstring)."""
    planar = problem == "planar"
    plan_config = PlanConfig(horizon_s=config.plan_horizon_s)
    state = initial_state(problem, theta0)
    goal_xy = np.asarray(GOALS[problem])
    a_max = plan_config.acceleration_bound(None, float(params.gravity))
    wipm = planning_problem(planar, plan_config, a_max, heading_given=False)
    steps, m = plan_config.steps, wipm.n_control
    goal = goal_state(problem, state, goal_xy)
    z0 = np.concatenate([state, np.zeros(m)])
    U0 = np.zeros((steps, m))
    goal_states = np.tile(goal, (steps + 1, 1))
    refs = refs_for(goal_states, params)
    ddp = plan_config.ddp
    solvers: dict[str, dict[str, Any]] = {}

    # --- offline plan: each solver's converged solve, timed over repetitions
    ours = ddp_solver_for(wipm, ddp)
    runs = _plan_runs(
        lambda: ours(z0, U0, params, refs), config.plan_reps_ours, f"{problem} plan ours"
    )
    solvers["ours"] = _plan_entry(*runs)
    croc = CrocoddylWIPM(wipm, params, steps, ddp.mu_init)
    runs = _plan_runs(
        lambda: croc.solve(z0, U0, params, goal_states, PEER_MAX_ITERATIONS, CROCODDYL_TH_STOP),
        config.plan_reps_peers,
        f"{problem} plan crocoddyl",
    )
    solvers["crocoddyl"] = _plan_entry(*runs)
    running, terminal = wipm.costs()
    numpy_peer = NumpyILQR(wipm.dynamics(), running, terminal, ddp)
    runs = _plan_runs(
        lambda: numpy_peer(z0, U0, params, refs),
        config.plan_reps_peers,
        f"{problem} plan numpy_ilqr",
    )
    solvers["numpy_ilqr"] = _plan_entry(*runs)
    plan_costs = {name: solvers[name]["plan_cost"] for name in SOLVERS}
    plan_check = _check("offline plan", problem, plan_costs, solvers)

    # the plan itself (the same cached solver: no compilation), to run the MPC along
    plan = plan_to_goal(state, params, goal_xy, planar=planar, config=plan_config)
    if (
        # (3-D: the plan's goal holds the x it arrived with; x is no part of that problem)
        not np.allclose(plan.goal_state[0 if planar else 1 :], goal[0 if planar else 1 :])
        or relative_difference(plan.cost, plan_costs["ours"]) > 1e-9
    ):
        raise RuntimeError("the benchmark's plan problem differs from plan_to_goal's")

    # --- MPC setup
    mpc_config = MPCConfig()
    horizon = mpc_config.steps
    mpc_wipm = mpc_problem(planar, mpc_config, plan.a_max, plan.theta_max)
    mpc_running, mpc_terminal = mpc_wipm.costs()
    budget = replace(mpc_config.ddp, max_iterations=mpc_config.iterations)

    # --- MPC steps at the default budget, along the plan from the plan's states
    warm_index = steps // 2  # each solver's throwaway first step, away from the timed window
    mpc_steps = min(config.mpc_steps, steps)

    def fresh_ours() -> ModelPredictiveController:
        return ModelPredictiveController(plan, mpc_config)

    croc_mpc = CrocoddylWIPM(mpc_wipm, params, horizon, budget.mu_init)
    numpy_mpc = NumpyILQR(mpc_wipm.dynamics(), mpc_running, mpc_terminal, budget)

    def croc_solve(x: np.ndarray, U: np.ndarray, prm: WIPMParams, s_refs: np.ndarray) -> Any:
        return croc_mpc.solve(x, U, prm, s_refs, budget.max_iterations, CROCODDYL_NO_STOP)

    def numpy_solve(x: np.ndarray, U: np.ndarray, prm: WIPMParams, s_refs: np.ndarray) -> Any:
        return numpy_mpc(x, U, prm, refs_for(s_refs, prm))

    makers: dict[str, Callable[[], Any]] = {
        "ours": fresh_ours,
        "crocoddyl": lambda: _PeerMPC(plan, horizon, croc_solve),
        "numpy_ilqr": lambda: _PeerMPC(plan, horizon, numpy_solve),
    }
    for name in SOLVERS:
        throwaway, timed = makers[name](), makers[name]()
        compile_s, times = _mpc_times(
            lambda i, timed=timed: timed.step(i, plan.states[i], params),
            lambda throwaway=throwaway: throwaway.step(warm_index, plan.states[warm_index], params),
            mpc_steps,
            f"{problem} MPC {name}",
        )
        solvers[name]["mpc_compile_s"] = compile_s
        solvers[name]["mpc_step_ms"] = stats_ms(times) | {"steps": mpc_steps}

    # --- MPC: one step run to convergence from the same shifted warm start (after the timed
    # steps, so that every solver's first MPC call, its compilation, falls in the timing's
    # throwaway step; a disagreement still raises and no figure is reported)
    converged_ddp = replace(
        mpc_config.ddp,
        max_iterations=PlanConfig().ddp.max_iterations,
        tolerance=PlanConfig().ddp.tolerance,
    )
    check_index = min(steps // 4, max(steps - 2, 1))
    previous = ModelPredictiveController(plan, mpc_config).step(
        check_index - 1, plan.states[check_index - 1], params
    )
    # the warm start the next step uses: the previous solution shifted by one (mpc.py)
    warm = np.vstack(
        [previous.predicted_controls[1:], plan.control_window(check_index - 1 + horizon, 1)]
    )
    mpc_refs = refs_for(plan.window(check_index, horizon + 1), params)
    x_check = plan.states[check_index]
    converged_results = {
        "ours": ddp_solver_for(mpc_wipm, converged_ddp)(x_check, warm, params, mpc_refs),
        "crocoddyl": CrocoddylWIPM(mpc_wipm, params, horizon, budget.mu_init).solve(
            x_check, warm, params, mpc_refs[0], PEER_MAX_ITERATIONS, CROCODDYL_TH_STOP_CONVERGED
        ),
        "numpy_ilqr": NumpyILQR(mpc_wipm.dynamics(), mpc_running, mpc_terminal, converged_ddp)(
            x_check, warm, params, mpc_refs
        ),
    }
    mpc_check = _check(
        "MPC step",
        problem,
        {name: float(r.cost) for name, r in converged_results.items()},
        {name: {"plan_converged": bool(r.converged)} for name, r in converged_results.items()},
    )
    mpc_check["index"] = check_index
    mpc_check["iterations"] = {name: int(r.iterations) for name, r in converged_results.items()}

    return {
        "solvers": solvers,
        "plan_steps": steps,
        "mpc_horizon": horizon,
        "mpc_iterations": mpc_config.iterations,
        "optimum_check": {"plan": plan_check, "mpc_step": mpc_check},
    }


def _check(
    what: str, problem: str, costs: dict[str, float], entries: dict[str, dict[str, Any]]
) -> dict[str, Any]:
    """The converged solves' costs agree with ours to :data:`COST_TOLERANCE` (raises if not)."""
    rel = {name: relative_difference(cost, costs["ours"]) for name, cost in costs.items()}
    converged = {name: bool(entries[name]["plan_converged"]) for name in costs}
    worst = max(rel.values())
    if worst > COST_TOLERANCE or not all(converged.values()):
        raise RuntimeError(
            f"{problem} {what}: the solvers do not reach the same optimum (costs {costs}, "
            f"relative differences {rel}, converged {converged}; tolerance {COST_TOLERANCE:g})"
        )
    return {
        "costs": costs,
        "rel_diff_to_ours": rel,
        "converged": converged,
        "max_rel_diff": worst,
        "tolerance": COST_TOLERANCE,
        "agree": True,
    }


def run(config: DDPBenchConfig) -> dict[str, Any]:
    """Both problems; keys ``theta0`` and one entry per problem (see :func:`bench_problem`)."""
    params, theta0 = krang_params()
    out: dict[str, Any] = {"theta0": theta0, "config": config.__dict__.copy()}
    for problem in PROBLEMS:
        out[problem] = bench_problem(problem, params, theta0, config)
    return out


__all__ = ["COST_TOLERANCE", "DDPBenchConfig", "PROBLEMS", "SOLVERS", "bench_problem", "run"]
