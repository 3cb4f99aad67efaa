"""A compiled peer of the MPC's DDP solve: the same algorithm and settings as
``controllers.optimizer.ddp`` as the MPC runs it, in numba, every derivative from JAX's autodiff
through the generated stage code of ``benchmarks.speed.stage_codegen``.

    python -m benchmarks.speed.compiled_ddp [--rounds 5] [--index 100 --index 400]

:func:`compiled_mpc_solver` builds, for one WIPM problem and ``DDPConfig``, one numba function
that runs ``DDPSolver._solve``'s loop: the warm start's rollout and cost, the backward pass with
the regularisation schedule (8), the line search (6)-(7) over the same step sizes (the largest
acceptable one, tried in decreasing order, which is the JAX solver's answer too), the stopping
test (9) and the iteration budget. Its per-step pieces are generated from jaxprs
(``benchmarks.speed.stage_codegen``, with ``fold``: the exact zeros of the Jacobians drop out):
a rollout step (dynamics and running cost), the terminal expansion (``jax.grad``,
``jax.hessian``, as the JAX solver takes them) and a backward step (the problem's own stage
derivatives, then ``controllers.optimizer.ddp.riccati_step``, the function the JAX solver's
backward scan runs).

It covers the settings the MPC uses (iLQR, no gradient norm) and refuses others. It is a
benchmark peer, as ``numpy_ilqr`` and ``crocoddyl_wipm`` are: the controllers run the JAX
solver. A test holds its trajectory to the JAX solver's on the MPC's windows
(tests/test_solvers_bench.py); the benchmark times both on the same window, interleaved, in
units (docs/performance.md §17).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any, NamedTuple

import numba
import numpy as np

from benchmarks.speed.stage_codegen import scalar_function


class CompiledSolve(NamedTuple):
    """The solve's result: ``X`` (N+1, n), ``U`` (N, m), the final cost, iterations done."""

    X: np.ndarray
    U: np.ndarray
    cost: float
    iterations: int


def _flat_params(params: Any) -> np.ndarray:
    import jax  # noqa: PLC0415

    return np.concatenate([np.ravel(np.asarray(a, dtype=float)) for a in jax.tree.leaves(params)])


def compiled_mpc_solver(wipm: Any, config: Any, params: Any) -> Callable[..., CompiledSolve]:
    """``solve(x0, U_init, s_ref[, params]) -> CompiledSolve`` for ``wipm``'s problem with
    ``config`` (``s_ref``: the (N+1, n) reference states; ``params``: ``lambda(q)``, whose
    pytree fixes the generated code's input layout; a solve may pass its own of that layout)."""
    import jax  # noqa: PLC0415
    import jax.numpy as jnp  # noqa: PLC0415

    if config.second_order or config.gradient_norm or config.grad_tolerance > 0:
        raise ValueError(
            "the compiled peer runs the MPC's settings: iLQR without the gradient norm"
        )
    from controllers.optimizer.ddp import riccati_step  # noqa: PLC0415

    n, m = wipm.n_state, wipm.n_control
    dynamics = wipm.dynamics()
    running, terminal = wipm.costs()
    jacobians, cost_derivatives = wipm.dynamics_derivatives(), wipm.running_derivatives()

    def backward_step(x: Any, u: Any, s: Any, p: Any, vx: Any, vxx: Any, mu: Any) -> Any:
        """The stage's derivatives and the recursion's step (``riccati_step``, iLQR)."""
        derivatives = (*cost_derivatives(x, u, (s, p)), *jacobians(x, u, p))
        vx_new, vxx_new, K, k, dv1, dv2, ok = riccati_step(derivatives, vx, vxx, mu, False)
        return vx_new, vxx_new, K, k, dv1, dv2, ok.astype(vx.dtype)

    def rollout_step(x: Any, u: Any, s: Any, p: Any) -> Any:
        return dynamics(x, u, p), running(x, u, (s, p))

    def terminal_expansion(x: Any, s: Any, p: Any) -> Any:
        ref = (s, p)
        return terminal(x, ref), jax.grad(terminal)(x, ref), jax.hessian(terminal)(x, ref)

    zeros_n, zeros_m = jnp.zeros(n), jnp.zeros(m)
    step, _, _ = scalar_function(rollout_step, zeros_n, zeros_m, zeros_n, params, fold=True)
    final, _, _ = scalar_function(terminal_expansion, zeros_n, zeros_n, params, fold=True)
    back, _, back_outputs = scalar_function(
        backward_step,
        zeros_n,
        zeros_m,
        zeros_n,
        params,
        zeros_n,
        jnp.eye(n),
        jnp.zeros(()),
        fold=True,
    )
    p_flat = _flat_params(params)
    alphas = np.asarray(config.alphas, dtype=float)
    max_iterations = int(config.max_iterations)
    tolerance, abs_tolerance = float(config.tolerance), float(config.abs_tolerance)
    mu_init, factor = float(config.mu_init), float(config.mu_factor)
    mu_min, mu_max = float(config.mu_min), float(config.mu_max)
    c = float(config.line_search_c)
    final_backward = bool(config.final_backward)
    # the backward step's outputs: V_x, V_xx, K, k, the two dV terms, ok
    if back_outputs != n + n * n + m * n + m + 3:
        raise AssertionError("the backward step's outputs are not the layout expected")
    o_K, o_k = n + n * n, n + n * n + m * n
    o_dv = o_k + m

    @numba.njit(cache=False, error_model="numpy")
    def terminal_at(x_end, s_end, P):  # noqa: ANN001, ANN202
        """The terminal cost, its gradient and Hessian at ``x_end``, in one vector."""
        zf = np.empty(2 * n + P.shape[0])
        zf[:n] = x_end
        zf[n : 2 * n] = s_end
        zf[2 * n :] = P
        fo = np.empty(1 + n + n * n)
        final(zf, fo)
        return fo

    @numba.njit(cache=False, error_model="numpy")
    def stops(ok, dv1, dv2, cost):  # noqa: ANN001, ANN202
        """Test (9) after a backward pass, or its failure."""
        return not ok or -(dv1 + dv2) <= tolerance * abs(cost) + abs_tolerance

    @numba.njit(cache=False, error_model="numpy")
    def trajectory(x0, U, X_ref, K, k, alpha, S, P, X_out, U_out, z, out):  # noqa: ANN001, ANN202, PLR0913
        """Rollout (6) from ``x0`` (``alpha`` < 0: the controls ``U`` open loop, ``K`` and
        ``k`` unread); returns the cost (1)."""
        steps = U.shape[0]
        X_out[0] = x0
        total = 0.0
        z[2 * n + m :] = P
        for t in range(steps):
            x = X_out[t]
            for a in range(m):
                v = U[t, a]
                if alpha >= 0.0:
                    v += alpha * k[t, a]
                    for j in range(n):
                        v += K[t, a, j] * (x[j] - X_ref[t, j])
                U_out[t, a] = v
            z[:n] = x
            z[n : n + m] = U_out[t]
            z[n + m : 2 * n + m] = S[t]
            step(z, out)
            X_out[t + 1] = out[:n]
            total += out[n]
        return total + terminal_at(X_out[steps], S[steps], P)[0]

    @numba.njit(cache=False, error_model="numpy")
    def backward(X, U, S, P, mu, K, k, z, out):  # noqa: ANN001, ANN202, PLR0913
        """The backward pass (2)-(5): (dv1, dv2, ok), the gains into ``K``, ``k``."""
        steps = U.shape[0]
        base = 2 * n + m + P.shape[0]
        z[base : base + n + n * n] = terminal_at(X[steps], S[steps], P)[1:]  # V_x, V_xx at N
        z[base + n + n * n] = mu
        dv1, dv2, ok = 0.0, 0.0, True
        z[2 * n + m : base] = P
        for t in range(steps - 1, -1, -1):
            z[:n] = X[t]
            z[n : n + m] = U[t]
            z[n + m : 2 * n + m] = S[t]
            back(z, out)
            z[base : base + n + n * n] = out[: n + n * n]
            for a in range(m):
                k[t, a] = out[o_k + a]
                for j in range(n):
                    K[t, a, j] = out[o_K + a * n + j]
            dv1 += out[o_dv]
            dv2 += out[o_dv + 1]
            ok = ok and out[o_dv + 2] != 0.0
        ok = ok and np.isfinite(dv1) and np.isfinite(dv2)
        return dv1, dv2, ok

    @numba.njit(cache=False, error_model="numpy")
    def increase(mu, dmu):  # noqa: ANN001, ANN202
        dmu = max(dmu * factor, factor)
        return max(mu * dmu, mu_min), dmu

    @numba.njit(cache=False, error_model="numpy")
    def decrease(mu, dmu):  # noqa: ANN001, ANN202
        dmu = min(dmu / factor, 1.0 / factor)
        mu = mu * dmu
        return (0.0 if mu < mu_min else mu), dmu

    @numba.njit(cache=False, error_model="numpy")
    def regularised(X, U, S, P, mu, dmu, K, k, z, out):  # noqa: ANN001, ANN202, PLR0913
        """Backward passes with mu increased until one succeeds (8); (dv1, dv2, ok, mu, dmu)."""
        while True:
            dv1, dv2, ok = backward(X, U, S, P, mu, K, k, z, out)
            if ok:
                return dv1, dv2, ok, mu, dmu
            mu2, dmu2 = increase(mu, dmu)
            if mu2 > mu_max or mu2 <= mu:
                return dv1, dv2, False, mu, dmu
            mu, dmu = mu2, dmu2

    @numba.njit(cache=False, error_model="numpy")
    def solve(x0, U_init, S, P):  # noqa: ANN001, ANN202
        steps = U_init.shape[0]
        X = np.empty((steps + 1, n))
        U = U_init.copy()
        K = np.zeros((steps, m, n))
        k = np.zeros((steps, m))
        X_new = np.empty((steps + 1, n))
        U_new = np.empty((steps, m))
        z = np.empty(2 * n + m + P.shape[0])
        out = np.empty(n + 1)
        zb = np.empty(2 * n + m + P.shape[0] + n + n * n + 1)
        ob = np.empty(back_outputs)
        # the warm start's rollout, then its backward pass (the first pass of the loop)
        cost = trajectory(x0, U_init, X, K, k, -1.0, S, P, X, U, z, out)
        mu, dmu = mu_init, 1.0
        dv1, dv2, ok, mu, dmu = regularised(X, U, S, P, mu, dmu, K, k, zb, ob)
        iterations = 0
        done = stops(ok, dv1, dv2, cost)
        while not done and iterations < max_iterations:
            accepted = False
            for alpha in alphas:
                new_cost = trajectory(x0, U, X, K, k, alpha, S, P, X_new, U_new, z, out)
                actual = cost - new_cost
                expected = -(alpha * dv1 + alpha * alpha * dv2)
                if np.isfinite(new_cost) and actual > 0 and actual >= c * expected:
                    accepted = True
                    break
            mu_up, dmu_up = increase(mu, dmu)
            stuck = (not accepted) and (mu_up > mu_max or mu_up <= mu)
            if accepted:
                X[:] = X_new
                U[:] = U_new
                cost = new_cost
                mu, dmu = decrease(mu, dmu)
            elif not stuck:
                mu, dmu = mu_up, dmu_up
            iterations += 1
            last = iterations >= max_iterations and not final_backward
            if stuck or last:
                break
            dv1, dv2, ok, mu, dmu = regularised(X, U, S, P, mu, dmu, K, k, zb, ob)
            done = stops(ok, dv1, dv2, cost)
        return X, U, cost, iterations

    def call(x0: Any, U_init: Any, s_ref: Any, params: Any = None) -> CompiledSolve:
        """A solve; ``params``: this step's ``lambda(q)`` (the one given to the builder if
        None)."""
        X, U, cost, iterations = solve(
            np.asarray(x0, dtype=float),
            np.asarray(U_init, dtype=float),
            np.ascontiguousarray(s_ref, dtype=float),
            p_flat if params is None else _flat_params(params),
        )
        return CompiledSolve(X, U, float(cost), int(iterations))

    call.raw = solve  # type: ignore[attr-defined]
    call.params = p_flat  # type: ignore[attr-defined]
    return call


def measure(rounds: int = 5, indices: tuple[int, ...] = (100, 400)) -> dict[str, dict[str, float]]:
    """Per MPC window (problem and plan index, ``ddp_parts.mpc_window``): the MPC's own step
    (``ModelPredictiveController.solve``: one call of its compiled step, warm-started from the
    plan's controls there) against the compiled peer's solve of the same problem (each with its
    Python wrapper), medians in us interleaved call by call; the largest differences of their
    predicted controls and states; ``unit_us``."""
    from benchmarks.speed.ddp_parts import mpc_window  # noqa: PLC0415
    from benchmarks.speed.yardstick import ReferenceStep, interleaved_rounds  # noqa: PLC0415
    from controllers.high_level.mpc import ModelPredictiveController, pack_inputs  # noqa: PLC0415

    reference = ReferenceStep()
    out: dict[str, dict[str, float]] = {}
    for problem in ("planar", "3d"):
        peer = None
        for index in indices:
            window = mpc_window(problem, index)
            mpc = ModelPredictiveController(window.plan)
            if peer is None:  # one peer per problem (its lambda(q) is the same)
                config = mpc.solver.config
                peer = compiled_mpc_solver(mpc.problem, config, window.params)
            x0 = np.asarray(window.X[0])
            host = pack_inputs(index, True, x0, window.params)  # warm start: the plan's
            U = np.asarray(window.U)
            s_ref = np.ascontiguousarray(window.refs[0])
            ours = mpc.solve(host)
            theirs = peer(x0, U, s_ref)
            functions = {
                "jax": lambda m=mpc, h=host: m.solve(h),
                "compiled": lambda p=peer, a=x0, b=U, r=s_ref: p(a, b, r),
            }
            med, unit = interleaved_rounds(functions, rounds, reference)
            out[f"{problem} {index}"] = {
                "jax_us": med["jax"],
                "compiled_us": med["compiled"],
                "max_dU": float(np.max(np.abs(theirs.U - ours.predicted_controls))),
                "max_dX": float(np.max(np.abs(theirs.X - ours.predicted_states))),
                "unit_us": unit,
            }
    return out


def main(argv: list[str] | None = None) -> int:
    from controllers.optimizer import jax_setup  # noqa: PLC0415

    jax_setup.configure()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument(
        "--index", type=int, action="append", help="plan indices of the windows (100 and 400)"
    )
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error("--rounds must be >= 1")
    indices = tuple(args.index) if args.index else (100, 400)
    print("the MPC step (2 DDP iterations), JAX against the compiled peer, median us (units):")
    for name, f in measure(args.rounds, indices).items():
        unit = f["unit_us"]
        print(
            f"  {name:11s} jax {f['jax_us']:6.1f} ({f['jax_us'] / unit:5.1f})  compiled "
            f"{f['compiled_us']:6.1f} ({f['compiled_us'] / unit:5.1f})  ratio "
            f"{f['jax_us'] / f['compiled_us']:4.2f}  max |dU| {f['max_dU']:.1e} "
            f"max |dX| {f['max_dX']:.1e}  (unit {unit:.1f} us)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
