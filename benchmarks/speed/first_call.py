"""The first plan and the first MPC step of a new process: compilation, or loading it from the
persistent caches (JAX's for the plan, numba's for the MPC's default backend,
``controllers.optimizer.numba_ddp``). Krang's ``lambda(q)``, the planar WIPM to 2 m (or with
``--problem 3d`` the 3-D one to (2, 1)). The MPC's time includes its construction, where the
numba backend traces the JAX functions and writes or loads its module.

    WIP_GYM_JAX_CACHE=$(mktemp -d) WIP_GYM_NUMBA_CACHE=$(mktemp -d) \
        python -m benchmarks.speed.first_call [--problem 3d]   # empty caches: compiles

Run it twice with the same directory: the second process loads what the first compiled.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks.speed.ddp_bench import GOALS, initial_state, krang_params
from controllers.high_level.mpc import ModelPredictiveController
from controllers.high_level.planning import plan_to_goal


def main(argv: list[str] | None = None) -> None:
    from controllers.optimizer import jax_setup

    jax_setup.configure()  # the solvers' JAX settings, before JAX starts
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problem", choices=("planar", "3d"), default="planar")
    problem = parser.parse_args(argv).problem
    params, theta0 = krang_params()
    state = initial_state(problem, theta0)
    start = time.perf_counter()
    goal = np.asarray(GOALS[problem])
    plan = plan_to_goal(state, params, goal, planar=problem == "planar")
    plan_s = time.perf_counter() - start
    start = time.perf_counter()
    mpc = ModelPredictiveController(plan)  # the numba backend writes or loads its module here
    mpc.step(0, plan.states[0], params)
    mpc_s = time.perf_counter() - start
    print(f"first plan {plan_s:.2f} s, MPC construction and first step {mpc_s:.2f} s ({problem})")


if __name__ == "__main__":
    main()
