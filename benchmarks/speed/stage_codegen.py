"""The DDP's stage functions (dynamics, Jacobians, cost derivatives) as straight-line scalar
code compiled by numba, generated from their jaxprs: how fast would a compiled DDP's per-step
work be, with JAX's autodiff still the source of every derivative?

    python -m benchmarks.speed.stage_codegen [--rounds 5]

``controllers.optimizer.scalar_codegen.scalar_function(fun, *example_args)`` writes a jaxpr
out as straight-line scalar code (one variable per entry) and numba compiles it.

The benchmark times, over the MPC's horizon (N = 100) at plan index 400, the per-step work of
a backward pass outside the recursion: the dynamics, its Jacobians (the problem's own
``dynamics_derivatives``: autodiff along the inputs it reads) and the running cost's
derivatives (``running_derivatives``), one generated call per step in a compiled loop, against
the same work in XLA as ``ddp_parts`` measures it (``backward`` minus ``backward_riccati``,
both net of nothing: their difference is the derivatives and the penalty's activity test).
A test holds the generated functions to JAX's on random inputs
(tests/test_solvers_bench.py).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

import numba
import numpy as np

from controllers.optimizer.scalar_codegen import scalar_function


def stage_function(wipm: Any, params: Any) -> tuple[Callable[..., None], int, int]:
    """The per-step work of ``wipm``'s backward pass outside the recursion, generated: from
    ``z = [x, u, s_ref, leaves of params]``, ``out = [f(x, u), f_x, f_u, l_x, l_u, l_xx, l_ux,
    l_uu]`` (the problem's own ``dynamics_derivatives`` and ``running_derivatives``)."""
    import jax.numpy as jnp  # noqa: PLC0415

    dynamics = wipm.dynamics()
    jacobians = wipm.dynamics_derivatives()
    cost_derivatives = wipm.running_derivatives()

    def stage(x: Any, u: Any, s_ref: Any, p: Any) -> Any:
        return dynamics(x, u, p), jacobians(x, u, p), cost_derivatives(x, u, (s_ref, p))

    n, m = wipm.n_state, wipm.n_control
    return scalar_function(stage, jnp.zeros(n), jnp.zeros(m), jnp.zeros(n), params)


def stage_rows(X: Any, U: Any, s_ref: Any, params: Any) -> np.ndarray:
    """One row of :func:`stage_function`'s input per step ``k < N``."""
    import jax  # noqa: PLC0415

    leaves = np.concatenate([np.ravel(np.asarray(a, dtype=float)) for a in jax.tree.leaves(params)])
    X, U, s_ref = (np.asarray(a, dtype=float) for a in (X, U, s_ref))
    steps = U.shape[0]
    return np.hstack([X[:steps], U, s_ref[:steps], np.tile(leaves, (steps, 1))])


def horizon_loop(stage: Callable[..., None]) -> Callable[[np.ndarray, np.ndarray], None]:
    """A compiled loop calling ``stage`` on every row: ``loop(Z, OUT)``."""

    @numba.njit(cache=False, error_model="numpy")
    def loop(Z: np.ndarray, OUT: np.ndarray) -> None:
        for k in range(Z.shape[0]):
            stage(Z[k], OUT[k])

    return loop


def measure(rounds: int = 5, index: int = 400) -> dict[str, dict[str, float]]:
    """Per MPC problem, us per pass over the horizon: ``generated`` (the compiled loop of the
    generated stage function) and ``xla`` (``ddp_parts``' ``backward`` minus
    ``backward_riccati``: the same derivatives inside XLA's backward scan), and ``unit_us``."""
    from benchmarks.speed.ddp_parts import _problem_calls, mpc_window  # noqa: PLC0415
    from benchmarks.speed.yardstick import ReferenceStep, interleaved_rounds  # noqa: PLC0415

    reference = ReferenceStep()
    out: dict[str, dict[str, float]] = {}
    for problem in ("planar", "3d"):
        window = mpc_window(problem, index)
        stage, _, outputs = stage_function(window.wipm, window.params)
        Z = stage_rows(window.X, window.U, window.refs[0], window.params)
        OUT = np.empty((Z.shape[0], outputs))
        loop = horizon_loop(stage)
        calls = _problem_calls(window)
        functions = {
            "generated": lambda: loop(Z, OUT),  # noqa: B023
            "backward": calls["backward"],
            "riccati": calls["backward_riccati"],
        }
        med, unit = interleaved_rounds(functions, rounds, reference)
        out[problem] = {
            "steps": float(Z.shape[0]),
            "generated": med["generated"],
            "xla": med["backward"] - med["riccati"],
            "unit_us": unit,
        }
    return out


def main(argv: list[str] | None = None) -> int:
    from controllers.optimizer import jax_setup  # noqa: PLC0415

    jax_setup.configure()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--index", type=int, default=400, help="the MPC window's plan index")
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error("--rounds must be >= 1")
    print("a backward pass's derivatives over the MPC's horizon, per pass (per step):")
    for problem, f in measure(args.rounds, args.index).items():
        steps = f["steps"]
        print(
            f"  {problem:6s} N={int(steps)}  generated {f['generated']:6.1f} us "
            f"({1e3 * f['generated'] / steps:4.0f} ns)  xla {f['xla']:6.1f} us "
            f"({1e3 * f['xla'] / steps:4.0f} ns)  (unit {f['unit_us']:.1f} us)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
