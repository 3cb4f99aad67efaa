"""The MPC step and the 3-D offline plan of the working tree against those of a git revision,
timed interleaved in one process, the MPC step in units (``benchmarks.speed.yardstick``).

    python -m benchmarks.speed.mpc_interleaved --base REV [--rounds 6] [--steps 200] [--plans 7]

The revision's ``controllers/optimizer/ddp.py``, ``controllers/optimizer/numba_ddp.py`` (so
that each version's numba backend writes its own module), ``controllers/simplified/
wipm_problem.py`` and ``controllers/high_level/mpc.py`` are loaded from ``git show REV:...`` as
modules of their own (their imports of one another redirected to each other; a revision without
``numba_ddp`` is not supported; both use this checkout's ``scalar_codegen``, so a change to the
code writer itself does not show here), so that both versions run side by side on
the same plan (``wip-bench solvers``' problems: Krang's ``lambda(q)``, the plan to (2, 0) planar and
(2, 1) 3-D). Per problem: each version's ``ModelPredictiveController`` along the plan's first
``--steps`` indices from the plan's states (``wip-bench solvers``' MPC workload), the versions
alternating round by round, a burst of warm reference steps every 50 MPC steps (the step after it
not counted); the median per round, then the median of the rounds. Then the 3-D plan
(``PlanConfig()``, N = 2000) solved ``--plans`` times by each version, alternating. Also printed:
the largest difference between the versions' predicted states and controls over 20 MPC steps off the
plan, and between their plans. On a shared machine only such interleaved figures compare.

Each version's MPC runs with its default settings; ``--backend jax`` or ``numba`` sets the working
tree's backend (``MPCConfig.backend``; numba is its default since the backend came, the JAX DDP
before), so that a change to either backend compares with a revision before it."""

from __future__ import annotations

import argparse
import dataclasses
import linecache
import subprocess
import sys
import time
import types
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[2]
# (module path, file) in the order they import one another
FILES = (
    ("controllers.optimizer.ddp", "controllers/optimizer/ddp.py"),
    ("controllers.optimizer.numba_ddp", "controllers/optimizer/numba_ddp.py"),
    ("controllers.simplified.wipm_problem", "controllers/simplified/wipm_problem.py"),
    ("controllers.high_level.mpc", "controllers/high_level/mpc.py"),
)


def load_revision(revision: str) -> dict[str, types.ModuleType]:
    """:data:`FILES` at ``revision`` as modules ``_rev_<name>`` (imports among them redirected)."""
    modules: dict[str, types.ModuleType] = {}
    for dotted, path in FILES:
        source = subprocess.run(
            ["git", "-C", str(REPO), "show", f"{revision}:{path}"],
            check=True,
            capture_output=True,
            text=True,
        ).stdout
        for other, _ in FILES:
            alias = f"_rev_{other.replace('.', '_')}"
            package, _, leaf = other.rpartition(".")
            source = source.replace(f"from {other} import", f"from {alias} import")
            source = source.replace(
                f"from {package} import {leaf}\n", f"import {alias} as {leaf}\n"
            )
        name = f"_rev_{dotted.replace('.', '_')}"
        module = types.ModuleType(name)
        module.__file__ = f"{revision}:{path}"
        # inspect.getsource (numba_ddp copies its driver's source) reads it from linecache
        linecache.cache[module.__file__] = (len(source), None, source.splitlines(True), path)
        sys.modules[name] = module
        exec(compile(source, module.__file__, "exec"), module.__dict__)  # noqa: S102
        modules[dotted] = module
    mpc = modules["controllers.high_level.mpc"]
    if mpc.numba_ddp is not modules["controllers.optimizer.numba_ddp"]:  # an import not redirected
        raise RuntimeError(f"{revision}'s mpc.py did not import its own numba_ddp")
    return modules


def _convert(problem: Any, wipm_problem: types.ModuleType) -> Any:
    """``problem`` (a ``WIPMProblem``) as the other version's class."""
    weights = wipm_problem.Weights(**problem.weights.__dict__)
    return wipm_problem.WIPMProblem(
        planar=problem.planar, dt=problem.dt, weights=weights, rate_input=problem.rate_input
    )


def main() -> None:
    from controllers.optimizer import jax_setup

    jax_setup.configure()  # before JAX starts
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", required=True, help="the git revision to compare against")
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--plans", type=int, default=7)
    parser.add_argument(
        "--backend", choices=("jax", "numba"), help="the working tree's MPC backend (its default)"
    )
    args = parser.parse_args()

    import jax  # noqa: PLC0415

    from benchmarks.speed.ddp_bench import (  # noqa: PLC0415
        GOALS,
        REFERENCE_EVERY,
        goal_state,
        initial_state,
        krang_params,
    )
    from benchmarks.speed.yardstick import ReferenceStep, times_between_bursts  # noqa: PLC0415
    from controllers.high_level import mpc  # noqa: PLC0415
    from controllers.high_level.planning import PlanConfig, plan_to_goal, planning_problem  # noqa: PLC0415
    from controllers.simplified import wipm_problem  # noqa: PLC0415
    from controllers.simplified.wipm_problem import refs_for  # noqa: PLC0415

    base = load_revision(args.base)
    versions = {"base": base["controllers.high_level.mpc"], "new": mpc}
    configs = {"base": None, "new": mpc.MPCConfig(backend=args.backend) if args.backend else None}
    params, theta0 = krang_params()
    reference = ReferenceStep()
    for _ in range(100):
        reference.sample()
    for problem in ("planar", "3d"):
        plan = plan_to_goal(
            initial_state(problem, theta0),
            params,
            np.asarray(GOALS[problem]),
            planar=problem == "planar",
        )
        off_plan = {}
        for name, module in versions.items():
            controller = module.ModelPredictiveController(plan, configs[name])
            controller.step(1000, plan.states[1000], params)  # compiles
            off_plan[name] = [
                controller.step(i, plan.states[i] + 0.01, params) for i in range(0, 400, 20)
            ]
        dX = max(
            float(np.max(np.abs(a.predicted_states - b.predicted_states)))
            for a, b in zip(off_plan["base"], off_plan["new"], strict=True)
        )
        dU = max(
            float(np.max(np.abs(a.predicted_controls - b.predicted_controls)))
            for a, b in zip(off_plan["base"], off_plan["new"], strict=True)
        )
        print(f"{problem}: max |X_base - X_new| {dX:.2e}, |U_base - U_new| {dU:.2e}", flush=True)
        medians: dict[str, list[float]] = {name: [] for name in versions}
        p99s: dict[str, list[float]] = {name: [] for name in versions}
        units: list[float] = []
        for _ in range(args.rounds):
            for name, module in versions.items():
                controller = module.ModelPredictiveController(plan, configs[name])
                controller.step(0, plan.states[0], params)

                def timed(i: int, controller: Any = controller, states: Any = plan.states) -> float:
                    start = time.perf_counter()
                    controller.step(i, states[i], params)
                    return time.perf_counter() - start

                times = times_between_bursts(
                    timed, range(args.steps), args.steps, REFERENCE_EVERY, reference, units
                )
                medians[name].append(float(np.median(times)))
                p99s[name].append(float(np.percentile(times, 99)))
        unit = float(np.median(units))
        for name in versions:
            per_round = np.round(np.array(medians[name]) / unit, 1).tolist()
            p99 = np.round(np.array(p99s[name]) / unit, 1).tolist()
            print(
                f"{problem} MPC step {name}: median {np.median(medians[name]) / unit:.1f} units "
                f"({np.median(medians[name]) * 1e6:.0f} us; rounds {per_round}; p99 {p99}; "
                f"unit {unit * 1e6:.1f} us)",
                flush=True,
            )

    config = PlanConfig()
    state = initial_state("3d", theta0)
    a_max = config.acceleration_bound(None, float(params.gravity))
    problem_new = planning_problem(False, config, a_max, heading_given=False)
    problems = {
        "base": _convert(problem_new, base["controllers.simplified.wipm_problem"]),
        "new": problem_new,
    }
    solver_for = {
        "base": base["controllers.simplified.wipm_problem"].ddp_solver_for,
        "new": wipm_problem.ddp_solver_for,
    }
    m = problem_new.n_control
    z0 = np.concatenate([state, np.zeros(m)])
    U0 = np.zeros((config.steps, m))
    goal = goal_state("3d", state, np.asarray(GOALS["3d"]))
    refs = refs_for(np.tile(goal, (config.steps + 1, 1)), params)
    # the settings the revision knows (a setting added since runs at the revision's behaviour)
    base_config = base["controllers.optimizer.ddp"].DDPConfig
    known = {f.name for f in dataclasses.fields(base_config)}
    dropped = sorted(set(config.ddp.__dict__) - known)
    if dropped:
        print(f"3d plan: {args.base} has no DDPConfig setting {dropped}: it runs without them")
    base_ddp = base_config(**{k: v for k, v in config.ddp.__dict__.items() if k in known})
    solvers = {
        "base": solver_for["base"](problems["base"], base_ddp),
        "new": solver_for["new"](problems["new"], config.ddp),
    }
    results = {name: solver(z0, U0, params, refs) for name, solver in solvers.items()}
    print(
        "3d plan: iterations",
        {name: int(r.iterations) for name, r in results.items()},
        f"max |X_base - X_new| {float(np.max(np.abs(results['base'].X - results['new'].X))):.2e}",
        f"|U_base - U_new| {float(np.max(np.abs(results['base'].U - results['new'].U))):.2e}",
        flush=True,
    )
    plan_times: dict[str, list[float]] = {name: [] for name in solvers}
    for _ in range(args.plans):
        for name, solver in solvers.items():
            start = time.perf_counter()
            jax.block_until_ready(solver(z0, U0, params, refs).U)
            plan_times[name].append(time.perf_counter() - start)
    for name, times in plan_times.items():
        print(
            f"3d plan {name}: median {np.median(times) * 1e3:.1f} ms "
            f"(runs {np.round(np.array(times) * 1e3, 1).tolist()})"
        )


if __name__ == "__main__":
    main()
