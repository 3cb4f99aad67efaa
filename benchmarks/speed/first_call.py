"""The first plan and the first MPC step of a new process: compilation, or loading it from the
persistent caches (JAX's for the plan, numba's for the MPC's default backend,
``controllers.optimizer.numba_ddp``). Planar WIPM with Krang's ``lambda(q)``, goal 2 m.

    WIP_GYM_JAX_CACHE=$(mktemp -d) WIP_GYM_NUMBA_CACHE=$(mktemp -d) \
        python -m benchmarks.speed.first_call   # empty caches: compiles

Run it twice with the same directory: the second process loads what the first compiled.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.speed.ddp_bench import GOALS, krang_params
from controllers.high_level.mpc import ModelPredictiveController
from controllers.high_level.planning import plan_to_goal


def main() -> None:
    from controllers.optimizer import jax_setup

    jax_setup.configure()  # the solvers' JAX settings, before JAX starts
    params, theta0 = krang_params()
    state = np.array([theta0, 0.0, 0.0, 0.0])
    start = time.perf_counter()
    plan = plan_to_goal(state, params, np.asarray(GOALS["planar"]), planar=True)
    plan_s = time.perf_counter() - start
    start = time.perf_counter()
    # its construction included: the numba backend traces and loads (or writes) its module
    mpc = ModelPredictiveController(plan)
    mpc.step(0, plan.states[0], params)
    mpc_s = time.perf_counter() - start
    print(f"first plan {plan_s:.2f} s, first MPC step {mpc_s:.2f} s")


if __name__ == "__main__":
    main()
