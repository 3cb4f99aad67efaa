"""Reference outputs of the offline plan and the MPC (the correctness guard of the DDP's speed
work): the same problems solved by the code being tested, compared with the outputs of
the code before that work, stored in ``tests/data/ddp_recorded.npz``.

The WIPM parameters are stored with the outputs (Krang's ``lambda(q)`` at its initial pose when
the file was made), so the comparison does not depend on the robot model. Regenerate (only after
a deliberate change of the results, with the reason in the commit message) with
``python -m tests.ddp_recorded``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from controllers.high_level.mpc import ModelPredictiveController, MPCConfig
from controllers.high_level.planning import Plan, PlanConfig, plan_to_goal
from controllers.simplified.wipm import WIPMParams

PATH = Path(__file__).parent / "data" / "ddp_recorded.npz"
GOALS = {"planar": (2.0, 0.0), "3d": (2.0, 1.0)}
MPC_STEPS = 20


def initial_state(problem: str, theta0: float) -> np.ndarray:
    if problem == "planar":
        return np.array([theta0, 0.0, 0.0, 0.0])
    return np.array([0.0, 0.0, theta0, 0.0, 0.0, 0.0, 0.0, 0.0])


def mpc_states(plan: Plan) -> np.ndarray:
    """A scripted sequence of measured states: the plan's, 0.1 s into the drive, disturbed by a
    fixed pattern (so that every MPC step has work to do)."""
    n = plan.states.shape[1]
    steps = np.arange(MPC_STEPS)[:, None]
    pattern = 0.02 * np.sin(0.7 * steps + np.arange(n)[None, :])
    return plan.states[10 : 10 + MPC_STEPS] + pattern


def params_to_arrays(params: WIPMParams) -> dict[str, np.ndarray]:
    return {f"param_{k}": np.asarray(v, dtype=float) for k, v in params._asdict().items()}


def params_from_arrays(data: dict[str, np.ndarray]) -> WIPMParams:
    values = {k: np.asarray(data[f"param_{k}"], dtype=float) for k in WIPMParams._fields}
    return WIPMParams(**{k: (v if v.ndim else np.float64(v)) for k, v in values.items()})


def compute(params: WIPMParams, theta0: float) -> dict[str, np.ndarray]:
    """Plan (N = 2000) and 20 warm-started MPC steps for both problems; the MPC's keys with
    the default backend (``{problem}_mpc_...``) and with the JAX reference
    (``jax_{problem}_mpc_...``)."""
    out: dict[str, np.ndarray] = {}
    for problem, goal in GOALS.items():
        planar = problem == "planar"
        plan = plan_to_goal(
            initial_state(problem, theta0),
            params,
            np.array(goal),
            planar=planar,
            config=PlanConfig(),
        )
        out[f"{problem}_plan_states"] = plan.states
        out[f"{problem}_plan_controls"] = plan.controls
        out[f"{problem}_plan_cost"] = np.array(plan.cost)
        out[f"{problem}_plan_iterations"] = np.array(plan.iterations)
        for prefix, config in (("", MPCConfig()), ("jax_", MPCConfig(backend="jax"))):
            mpc = ModelPredictiveController(plan, config)
            controls, predicted, costs, accepted = [], [], [], []
            for i, state in enumerate(mpc_states(plan)):
                step = mpc.step(10 + i, state, params)
                controls.append(step.control)
                predicted.append(step.predicted_states)
                costs.append(step.cost)
                accepted.append(step.accepted)
            out[f"{prefix}{problem}_mpc_controls"] = np.array(controls)
            out[f"{prefix}{problem}_mpc_predicted_states"] = np.array(predicted)
            out[f"{prefix}{problem}_mpc_costs"] = np.array(costs)
            out[f"{prefix}{problem}_mpc_accepted"] = np.array(accepted)
    return out


def _krang() -> tuple[WIPMParams, float]:
    from benchmarks.speed.ddp_bench import krang_params

    return krang_params()


def main() -> None:
    from controllers.optimizer import jax_setup

    jax_setup.configure()  # the solvers' JAX settings, before JAX starts
    params, theta0 = _krang()
    computed = compute(params, theta0)
    # recorded from the JAX reference backend (its keys without the prefix)
    recorded = {
        key.removeprefix("jax_"): value
        for key, value in computed.items()
        if "_mpc_" not in key or key.startswith("jax_")
    }
    data = recorded | params_to_arrays(params) | {"theta0": np.array(theta0)}
    np.savez_compressed(PATH, **data)
    print(f"wrote {PATH}")


if __name__ == "__main__":
    main()
