"""Where the MPC step's time goes: its pieces jitted alone, in units
(``benchmarks.speed.yardstick``).

    python -m benchmarks.speed.ddp_parts [--rounds 3] [--index 400]

On Krang's WIPM (``benchmarks.speed.ddp_bench``: the plan to (2, 0) planar, (2, 1) 3-D), the
MPC's problem at plan index ``--index`` from the plan's state plus 0.01 (``N = 100``; at 400
the 3-D plan's acceleration penalty is inactive along the window, the planar plan's active; at
100 both are active), each piece timed as its own jitted call (median of 200 calls, then the
median over ``--rounds`` interleaved rounds):

* ``empty_call``: a jitted call with the solver's inputs that reads one entry: the floor;
* ``rollout``: one ``lax.scan`` of the dynamics over the horizon;
* ``cost``: the trajectory cost (``trajectory_cost``: a ``lax.map`` of the running cost);
* ``backward``: one backward pass (derivatives of every step and the Riccati recursion);
* ``backward_quadratic``: the same with the running cost's derivatives of its quadratic terms
  only (the acceleration and pitch penalty's left out: its activity test and, where active, its
  Hessian);
* ``backward_riccati``: the same again with the dynamics' Jacobians replaced by stand-ins of
  the same shapes that cost nothing (``I + 1e-3 dt 1 x'`` and ``dt u_0 1``): the Riccati
  recursion (2)-(5) and the loop alone, the floor of a backward pass in XLA:CPU's code;
* ``solve_0``, ``solve_1``, ``solve_2``: the MPC's DDP with a budget of 0, 1, 2 iterations
  (0: the warm start's rollout, its cost and one backward pass).

A piece's cost minus ``empty_call`` over the horizon is its cost per step of the loop.
Measured (2 shared cores, 2026-11-27, two runs of ``--rounds 5``; units of 12.2 to 18.8 us),
planar / 3-D: empty_call 1.1 / 0.7 to 1.2, rollout 3.0 / 4.1 to 6.3, cost 3.8 to 5.2 / 2.7 to
3.7, backward 10.6 to 11.1 / 12.3 to 14.0, backward_quadratic 4.5 to 4.7 / 10.7 to 11.2,
backward_riccati 2.6 to 2.7 / 6.0, solve_2 20.0 to 21.8 / 32.1 to 37.4 units (the backward
passes then returned their gains alone, and XLA dropped the adjoint and the expected change;
now they return the whole pass, and the MPC's settings leave out the gradient norm's adjoint:
backward 11.0 / 16.3, backward_riccati 5.9 / 8.4 in one run, docs/performance.md §16). So in
the 3-D backward pass about half is the Riccati recursion and the loop (about 1 us per step: the
floor of this code in XLA:CPU), most of the rest the dynamics' Jacobians; in the planar one
more than half is the penalty's activity test (an evaluation of the model that XLA does not
share with the Jacobian's), inactive along that window. With
XLA's small-loop option (``controllers.optimizer.jax_setup``) a loop step costs little beyond
its arithmetic (the option off doubles ``cost``). Separate top-level loops of one call cost
more than the same loops nested in one (four rollouts as four loops: 130 us, nested in one
loop: 47 us, one alone: 31 us), which is why ``controllers.optimizer.ddp`` runs the warm
start's rollout inside its iteration loop.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from benchmarks.speed.yardstick import ReferenceStep, median_call_us

PIECES = (
    "empty_call",
    "rollout",
    "cost",
    "backward",
    "backward_quadratic",
    "backward_riccati",
    "solve_0",
    "solve_1",
    "solve_2",
)


class MPCWindow(NamedTuple):
    """The MPC's problem at one plan index: the WIPM problem, its plan, the plan's start, the
    trajectory of the plan's controls from the plan's state there plus 0.01, Krang's
    ``lambda(q)`` and the per-step references."""

    wipm: Any
    plan: Any
    start: np.ndarray
    X: Any
    U: Any
    params: Any
    refs: Any


def window_arguments(description: str, argv: list[str] | None) -> tuple[int, tuple[int, ...]]:
    """``(rounds, indices)`` from a benchmark's ``--rounds`` (default 5, at least 1) and
    repeatable ``--index`` (the windows' plan indices, default 100 and 400) arguments."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument(
        "--index", type=int, action="append", help="plan indices of the windows (100 and 400)"
    )
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error("--rounds must be >= 1")
    return args.rounds, tuple(args.index) if args.index else (100, 400)


def mpc_window(problem: str, index: int = 400) -> MPCWindow:
    """The MPC workload of this module (and of ``riccati_floor``, ``stage_codegen``,
    ``mpc_backends``): Krang's WIPM, the plan to ``GOALS[problem]``, the window of ``N`` steps
    at plan ``index`` from the plan's state plus 0.01 (off the plan: every iteration has
    work)."""
    import jax  # noqa: PLC0415
    import jax.numpy as jnp  # noqa: PLC0415

    from benchmarks.speed.ddp_bench import GOALS, initial_state, krang_params  # noqa: PLC0415
    from controllers.high_level.mpc import MPCConfig, mpc_problem  # noqa: PLC0415
    from controllers.high_level.planning import plan_to_goal  # noqa: PLC0415
    from controllers.optimizer.ddp import rollout  # noqa: PLC0415
    from controllers.simplified.wipm_problem import refs_for  # noqa: PLC0415

    params, theta0 = krang_params()
    planar = problem == "planar"
    start = initial_state(problem, theta0)
    plan = plan_to_goal(start, params, np.array(GOALS[problem]), planar=planar)
    config = MPCConfig()
    wipm = mpc_problem(planar, config, plan.a_max, plan.theta_max)
    horizon = config.steps
    if not 0 <= index < len(plan.states):
        raise ValueError(f"index {index} is outside the plan's {len(plan.states)} states")
    refs = jax.tree.map(jnp.asarray, refs_for(plan.window(index, horizon + 1), params))
    x0 = jnp.asarray(plan.states[index] + 0.01)
    U = jnp.asarray(plan.control_window(index, horizon))
    X = rollout(wipm.dynamics(), x0, U, params)
    return MPCWindow(wipm, plan, start, X, U, params, refs)


def _problem_calls(window: MPCWindow) -> dict[str, Callable[[], Any]]:
    """The pieces of :data:`PIECES` of one window's problem as argument-free calls."""
    import jax  # noqa: PLC0415
    import jax.numpy as jnp  # noqa: PLC0415

    from controllers.high_level.mpc import MPCConfig  # noqa: PLC0415
    from controllers.optimizer.ddp import DDPConfig, rollout, trajectory_cost  # noqa: PLC0415
    from controllers.simplified.wipm_problem import ddp_solver_for  # noqa: PLC0415

    wipm, X, U, params, refs = window.wipm, window.X, window.U, window.params, window.refs
    x0 = X[0]
    dynamics = wipm.dynamics()
    running, terminal = wipm.costs()
    base = MPCConfig().ddp
    solvers = {
        it: ddp_solver_for(wipm, DDPConfig(**{**base.__dict__, "max_iterations": it}))
        for it in (0, 1, 2)
    }
    mu = jnp.asarray(1e-3)
    quadratic, riccati = _ablated_solvers(wipm, base)
    jitted = {
        "empty_call": jax.jit(lambda X, U, p, r: X[0]),
        "rollout": jax.jit(lambda X, U, p, r: rollout(dynamics, X[0], U, p)),
        "cost": jax.jit(lambda X, U, p, r: trajectory_cost(running, terminal, X, U, r)),
        "backward": jax.jit(lambda X, U, p, r: solvers[2]._backward(X, U, p, r, mu)),
        "backward_quadratic": jax.jit(lambda X, U, p, r: quadratic._backward(X, U, p, r, mu)),
        "backward_riccati": jax.jit(lambda X, U, p, r: riccati._backward(X, U, p, r, mu)),
    }
    # the backward passes return the whole pass (gains, expected change, gradient norm, ok):
    # returning the gains alone let XLA drop the adjoint and the expected change as dead code
    calls: dict[str, Callable[[], Any]] = {
        name: (lambda f=f: jax.block_until_ready(f(X, U, params, refs)))
        for name, f in jitted.items()
    }
    for it, solver in solvers.items():
        calls[f"solve_{it}"] = lambda s=solver: jax.block_until_ready(
            s.jitted(x0, U, params, refs).U
        )
    return calls


def _ablated_solvers(wipm: Any, config: Any) -> tuple[Any, Any]:
    """Solvers of ``wipm`` whose backward pass leaves out work (``backward_quadratic``,
    ``backward_riccati``: the module docstring); their results are not the problem's. For the
    MPC's problems (no rate input)."""
    if wipm.rate_input:
        raise ValueError("the ablated solvers are written for problems without the rate input")
    import jax.numpy as jnp  # noqa: PLC0415

    from controllers.optimizer.ddp import make_ddp_solver  # noqa: PLC0415

    n, m, dt = wipm.n_state, wipm.n_control, wipm.dt
    q, r = np.asarray(wipm.weights.q), np.asarray(wipm.weights.r)

    def quadratic_derivatives(z: Any, w: Any, ref: Any) -> tuple[Any, ...]:
        s_ref, _ = ref
        return (
            2.0 * dt * q * (z - s_ref),
            2.0 * dt * r * w,
            jnp.diag(2.0 * dt * q),
            jnp.zeros((m, n)),
            jnp.diag(2.0 * dt * r),
        )

    def stand_in_jacobians(z: Any, w: Any, params: Any) -> tuple[Any, Any]:
        # depends on the inputs, so that XLA cannot fold the recursion's products away
        return jnp.eye(n) + 1e-3 * dt * jnp.outer(jnp.ones(n), z), dt * w[0] * jnp.ones((n, m))

    running, terminal = wipm.costs()
    dynamics, jacobians = wipm.dynamics(), wipm.dynamics_derivatives()
    quadratic = make_ddp_solver(
        dynamics, running, terminal, config, quadratic_derivatives, jacobians
    )
    riccati = make_ddp_solver(
        dynamics, running, terminal, config, quadratic_derivatives, stand_in_jacobians
    )
    return quadratic, riccati


def measure(rounds: int = 3, index: int = 400) -> dict[str, dict[str, float]]:
    """``{planar|3d: {piece: units}}`` and each problem's ``unit_us``."""
    reference = ReferenceStep()
    out: dict[str, dict[str, float]] = {}
    for problem in ("planar", "3d"):
        calls = _problem_calls(mpc_window(problem, index))
        samples: dict[str, list[float]] = {name: [] for name in PIECES}
        units: list[float] = []
        for _ in range(rounds):
            for name in PIECES:
                samples[name].append(median_call_us(calls[name]))
                units.append(float(np.median(reference.burst(50)) * 1e6))
        unit = float(np.median(units))
        out[problem] = {name: float(np.median(v)) / unit for name, v in samples.items()}
        out[problem]["unit_us"] = unit
    return out


def main() -> None:
    from controllers.optimizer import jax_setup

    jax_setup.configure()  # the solvers' JAX settings, before JAX starts
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--index", type=int, default=400, help="the plan index of the window")
    args = parser.parse_args()
    for problem, pieces in measure(args.rounds, args.index).items():
        unit = pieces.pop("unit_us")
        print(
            f"{problem} (unit {unit:.1f} us): "
            + ", ".join(f"{name} {value:.1f}" for name, value in pieces.items())
        )


if __name__ == "__main__":
    main()
