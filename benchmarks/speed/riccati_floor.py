"""The DDP's Riccati recursion in XLA:CPU's code against the same recursion compiled as scalar
loops: would a backward pass outside XLA reach the MPC's speed target?

    python -m benchmarks.speed.riccati_floor [--rounds 5] [--index 400]

Both sides run the recursion (2)-(5) of ``controllers.optimizer.ddp`` as the MPC and the plan
run it (iLQR: the Q-terms from ``F = [f_x f_u]``, ``Q_uu + mu I`` solved by its Cholesky factor,
the improved value update, the expected change; no adjoint recursion, since
``DDPConfig.gradient_norm`` is False there) over stage derivatives *stored* in arrays, so that
neither computes a derivative and the same floats go in:

* ``compiled``: :func:`compiled_recursion`, the same arithmetic as loops in numba with the
  state and control sizes fixed when it compiles (so that LLVM unrolls and vectorises the small
  products), reassociation allowed (NaN and inf semantics kept: the positive-definiteness test
  needs them), minus an empty compiled function of the same arguments (numba's dispatch);
* ``xla stored``: ``DDPSolver._backward`` itself, jitted, with the stage derivatives read from
  the per-step references (:func:`stored_backward`), minus an empty jitted call with the same
  inputs (the call's floor);
* ``xla stand-ins`` (the MPC's cases): ``benchmarks.speed.ddp_parts``' ``backward_riccati``
  (the whole pass returned) minus its ``empty_call``: the recursion with Jacobian stand-ins
  computed in the loop, which reads no stored arrays.

A per-step figure of a few hundred nanoseconds against one of about a microsecond says which
compiler's code is the floor (docs/performance.md §16).

The inputs are the MPC's problem at plan index ``--index`` (``benchmarks.speed.ddp_parts``:
Krang's WIPM, ``N = 100``, the state 0.01 off the plan) with the problem's own derivatives, and
the 3-D offline plan's problem at its solution (``N = 2000``, the rate input: ``n = 10``).
Medians of 200 rounds that call each variant in turn (``interleaved_median_us``: the
machine's speed drifts within seconds), then the median of ``--rounds`` such runs.
A test holds the compiled recursion to ``_backward`` on the same inputs
(tests/test_solvers_bench.py).
"""

from __future__ import annotations

import argparse
import functools
from collections.abc import Callable
from typing import Any, NamedTuple

import numba
import numpy as np

from benchmarks.speed.ddp_parts import MPCWindow, _problem_calls, mpc_window
from benchmarks.speed.yardstick import ReferenceStep, interleaved_rounds

# reassociation and contraction (FMA) allowed; not ``nnan``/``ninf``: the recursion tests for them
_FASTMATH = {"reassoc", "contract", "nsz", "arcp"}


class StageInputs(NamedTuple):
    """The recursion's inputs: per-step derivatives (leading axis ``N``) and the terminal value
    expansion."""

    fx: np.ndarray  # (N, n, n)
    fu: np.ndarray  # (N, n, m)
    lx: np.ndarray  # (N, n)
    lu: np.ndarray  # (N, m)
    lxx: np.ndarray  # (N, n, n)
    lux: np.ndarray  # (N, m, n)
    luu: np.ndarray  # (N, m, m)
    vx: np.ndarray  # (n,) terminal V_x
    vxx: np.ndarray  # (n, n) terminal V_xx


class RecursionResult(NamedTuple):
    K: np.ndarray
    k: np.ndarray
    dv1: float
    dv2: float
    ok: bool
    grad_norm: float


@functools.cache
def compiled_recursion(
    n: int, m: int, gradient: bool = False
) -> Callable[..., tuple[float, float, bool, float]]:
    """The recursion (2)-(5) for ``n`` states and ``m`` controls, compiled (numba) with the
    sizes as constants: ``recursion(fx, fu, lx, lu, lxx, lux, luu, vx, vxx, mu, K, k)`` fills
    ``K`` (N, m, n) and ``k`` (N, m) and returns ``(dv1, dv2, ok, grad_norm)`` as
    ``DDPSolver._backward`` does with ``DDPConfig.gradient_norm = gradient`` (False, as the MPC
    and the plan run it: no adjoint recursion, ``grad_norm`` NaN)."""
    if n < 1 or m < 1:
        raise ValueError(f"need n >= 1 and m >= 1, got n={n}, m={m}")
    p = n + m

    @numba.njit(fastmath=_FASTMATH, cache=False, error_model="numpy")
    def recursion(fx, fu, lx, lu, lxx, lux, luu, vx_end, vxx_end, mu, K, k):  # noqa: ANN001, ANN202, PLR0913
        steps = fx.shape[0]
        vx = vx_end.copy()
        vxx = 0.5 * (vxx_end + vxx_end.T)  # a Hessian: the products below read its upper half
        lam = vx_end.copy()
        lam_new = np.empty(n)
        F = np.empty((n, p))
        VF = np.empty((n, p))
        Q = np.empty((p, p))
        q = np.empty(p)
        A = np.empty((m, m))  # Q_uu + mu I, then its Cholesky factor (lower)
        B = np.empty((m, n + 1))  # [Q_u Q_ux], then the solution
        quu = np.empty((m, m))
        qk = np.empty(m)
        W = np.empty((m, n))  # Q_uu K
        dv1 = 0.0
        dv2 = 0.0
        ok = True
        gmax = 0.0
        for t in range(steps - 1, -1, -1):
            for i in range(n):
                for j in range(n):
                    F[i, j] = fx[t, i, j]
                for j in range(m):
                    F[i, n + j] = fu[t, i, j]
            # (2): F' V_x and F' V_xx F (V_xx symmetric: the upper triangle, mirrored)
            for i in range(n):
                for b in range(p):
                    s = 0.0
                    for j in range(n):
                        s += vxx[i, j] * F[j, b]
                    VF[i, b] = s
            for a in range(p):
                s = 0.0
                for i in range(n):
                    s += F[i, a] * vx[i]
                q[a] = s
                for b in range(a, p):
                    s = 0.0
                    for i in range(n):
                        s += F[i, a] * VF[i, b]
                    Q[a, b] = s
                    Q[b, a] = s
            for a in range(m):
                for b in range(m):
                    quu[a, b] = 0.5 * (luu[t, a, b] + luu[t, b, a]) + Q[n + a, n + b]
                    A[a, b] = quu[a, b] + (mu if a == b else 0.0)
                B[a, 0] = lu[t, a] + q[n + a]
                for j in range(n):
                    B[a, j + 1] = lux[t, a, j] + Q[n + a, j]
            # (3): Cholesky factor of Q_uu + mu I, then the solve for [Q_u Q_ux]
            for j in range(m):
                pivot = A[j, j]
                for c in range(j):
                    pivot -= A[j, c] * A[j, c]
                if not pivot > 0.0:
                    ok = False
                A[j, j] = np.sqrt(pivot)
                for i in range(j + 1, m):
                    off = A[i, j]
                    for c in range(j):
                        off -= A[i, c] * A[j, c]
                    A[i, j] = off / A[j, j]
            for col in range(n + 1):
                for i in range(m):
                    s = B[i, col]
                    for c in range(i):
                        s -= A[i, c] * B[c, col]
                    B[i, col] = s / A[i, i]
                for i in range(m - 1, -1, -1):
                    s = B[i, col]
                    for c in range(i + 1, m):
                        s -= A[c, i] * B[c, col]
                    B[i, col] = s / A[i, i]
            for a in range(m):
                k[t, a] = -B[a, 0]
                if not np.isfinite(B[a, 0]):
                    ok = False
                for j in range(n):
                    K[t, a, j] = -B[a, j + 1]
                    if not np.isfinite(B[a, j + 1]):
                        ok = False
            # (5)
            for a in range(m):
                s = 0.0
                for b in range(m):
                    s += quu[a, b] * k[t, b]
                qk[a] = s
                dv1 += k[t, a] * (lu[t, a] + q[n + a])
                dv2 += 0.5 * k[t, a] * s
                for j in range(n):
                    s = 0.0
                    for b in range(m):
                        s += quu[a, b] * K[t, b, j]
                    W[a, j] = s
            if gradient:
                # the gradient dJ/du and the adjoint (they read lam, the next step's adjoint)
                for a in range(m):
                    s = lu[t, a]
                    for i in range(n):
                        s += fu[t, i, a] * lam[i]
                    # jnp.maximum's NaN semantics: a NaN gradient makes the norm NaN, and stays
                    if not abs(s) <= gmax and gmax == gmax:
                        gmax = abs(s)
                for j in range(n):
                    s = lx[t, j]
                    for i in range(n):
                        s += fx[t, i, j] * lam[i]
                    lam_new[j] = s
                lam[:] = lam_new
            # (4): V_x, V_xx with Q_ux = lux + Q[n:, :n], the upper triangle mirrored
            for i in range(n):
                s = lx[t, i] + q[i]
                for a in range(m):
                    qux_ai = lux[t, a, i] + Q[n + a, i]
                    s += K[t, a, i] * (qk[a] + lu[t, a] + q[n + a]) + qux_ai * k[t, a]
                vx[i] = s
            for i in range(n):
                for j in range(i, n):
                    s = 0.5 * (lxx[t, i, j] + lxx[t, j, i]) + Q[i, j]
                    for a in range(m):
                        s += (
                            K[t, a, i] * W[a, j]
                            + K[t, a, i] * (lux[t, a, j] + Q[n + a, j])
                            + (lux[t, a, i] + Q[n + a, i]) * K[t, a, j]
                        )
                    vxx[i, j] = s
                    vxx[j, i] = s
        ok = ok and np.isfinite(dv1) and np.isfinite(dv2)
        return dv1, dv2, ok, (gmax if gradient else np.nan)

    return recursion


def run_compiled(inputs: StageInputs, mu: float, gradient: bool = False) -> RecursionResult:
    """:func:`compiled_recursion` on ``inputs``, its outputs allocated here."""
    steps, n, m = inputs.fu.shape
    K, k = np.empty((steps, m, n)), np.empty((steps, m))
    dv1, dv2, ok, gmax = compiled_recursion(n, m, gradient)(*inputs, float(mu), K, k)
    return RecursionResult(K, k, float(dv1), float(dv2), bool(ok), float(gmax))


class StoredBackward(NamedTuple):
    """``call(mu)``: ``DDPSolver._backward`` on stored inputs, jitted, its result ready (a JAX
    ``_Backward``); ``floor(mu)``: a jitted call with the same inputs that reads one entry."""

    call: Callable[[float], Any]
    floor: Callable[[float], Any]


def as_result(bp: Any) -> RecursionResult:
    """A JAX backward pass's result as NumPy and floats."""
    return RecursionResult(
        np.asarray(bp.K),
        np.asarray(bp.k),
        float(bp.dv1),
        float(bp.dv2),
        bool(bp.ok),
        float(bp.grad_norm),
    )


def stored_backward(inputs: StageInputs, gradient: bool = False) -> StoredBackward:
    """``DDPSolver._backward`` on ``inputs``, jitted (:class:`StoredBackward`), with
    ``DDPConfig.gradient_norm = gradient``."""
    import jax  # noqa: PLC0415
    import jax.numpy as jnp  # noqa: PLC0415

    from controllers.optimizer.ddp import DDPConfig, DDPSolver  # noqa: PLC0415

    class StoredDerivatives(DDPSolver):
        """A solver whose stage derivatives are the stored ones the references carry (the
        recursion alone: nothing is differentiated)."""

        def _stage_derivatives(self, x: Any, u: Any, r: Any, params: Any) -> tuple:
            lx, lu, lxx, lux, luu, fx, fu = r
            return lx, lu, lxx, lux, luu, fx, fu

    steps, n, m = inputs.fu.shape

    def pad(a: np.ndarray, last: np.ndarray) -> np.ndarray:
        return np.concatenate([a, last[None]], axis=0)

    # the trajectory is all zeros (the recursion reads none of it); terminal(x, r) =
    # r_lx . x + x' r_lxx x / 2 with V_x and V_xx in the terminal row: at x_N = 0 its gradient
    # is V_x and its Hessian V_xx
    refs = (
        pad(inputs.lx, inputs.vx),
        pad(inputs.lu, np.zeros(m)),
        pad(inputs.lxx, inputs.vxx),
        pad(inputs.lux, np.zeros((m, n))),
        pad(inputs.luu, np.zeros((m, m))),
        pad(inputs.fx, np.zeros((n, n))),
        pad(inputs.fu, np.zeros((n, m))),
    )

    def terminal(x: Any, r: Any) -> Any:
        return jnp.dot(r[0], x) + 0.5 * jnp.dot(x, r[2] @ x)

    def unused(*_: Any) -> Any:
        raise AssertionError("the stored recursion evaluates no dynamics or running cost")

    config = DDPConfig(second_order=False, gradient_norm=gradient)
    solver = StoredDerivatives(unused, unused, terminal, config)
    X = jnp.zeros((steps + 1, n))
    U = jnp.zeros((steps, m))
    refs_j = jax.tree.map(jnp.asarray, refs)
    backward = jax.jit(lambda X, U, r, mu: solver._backward(X, U, None, r, mu))
    empty = jax.jit(lambda X, U, r, mu: X[0])
    return StoredBackward(
        call=lambda mu: jax.block_until_ready(backward(X, U, refs_j, jnp.asarray(mu))),
        floor=lambda mu: jax.block_until_ready(empty(X, U, refs_j, jnp.asarray(mu))),
    )


def problem_inputs(solver: Any, X: Any, U: Any, params: Any, refs: Any) -> StageInputs:
    """The stage derivatives of ``solver``'s problem along ``(X, U)`` (its own
    ``_stage_derivatives``, vmapped over the steps) and its terminal value expansion."""
    import jax  # noqa: PLC0415

    if solver.config.second_order:
        raise ValueError("the stored recursion is the iLQR one (second_order=False)")
    head = jax.tree.map(lambda r: r[:-1], refs)
    last = jax.tree.map(lambda r: r[-1], refs)
    derivatives = jax.vmap(lambda x, u, r: solver._stage_derivatives(x, u, r, params))(
        X[:-1], U, head
    )
    lx, lu, lxx, lux, luu, fx, fu = (np.asarray(a) for a in derivatives[:7])
    vx = np.asarray(jax.grad(solver.terminal)(X[-1], last))
    vxx = np.asarray(jax.hessian(solver.terminal)(X[-1], last))
    return StageInputs(fx, fu, lx, lu, lxx, lux, luu, vx, vxx)


def _cases(index: int) -> dict[str, tuple[StageInputs, MPCWindow | None]]:
    """The MPC's problems at plan ``index`` (planar and 3-D, with their windows) and the 3-D
    plan's at its solution."""
    import jax  # noqa: PLC0415
    import jax.numpy as jnp  # noqa: PLC0415

    from benchmarks.speed.ddp_bench import GOALS, goal_state  # noqa: PLC0415
    from controllers.high_level.mpc import MPCConfig  # noqa: PLC0415
    from controllers.high_level.planning import PlanConfig, planning_problem  # noqa: PLC0415
    from controllers.simplified.wipm_problem import ddp_solver_for, refs_for  # noqa: PLC0415

    cases: dict[str, tuple[StageInputs, MPCWindow | None]] = {}
    for problem in ("planar", "3d"):
        window = mpc_window(problem, index)
        wipm, plan, start, X, U, params, refs = window
        solver = ddp_solver_for(wipm, MPCConfig().ddp)
        cases[f"mpc {problem}"] = (problem_inputs(solver, X, U, params, refs), window)
        if problem == "3d":
            # the plan's problem (the rate input: the control joins the state) at its solution,
            # from the plan's start to plan_to_goal's goal (heading free)
            plan_config = PlanConfig()
            steps, m = plan_config.steps, 2
            planner = ddp_solver_for(
                planning_problem(False, plan_config, plan.a_max, False), plan_config.ddp
            )
            goal = goal_state(problem, start, np.asarray(GOALS[problem]))
            plan_refs = jax.tree.map(jnp.asarray, refs_for(np.tile(goal, (steps + 1, 1)), params))
            z0 = np.concatenate([start, np.zeros(m)])
            solved = planner(z0, np.zeros((steps, m)), params, plan_refs)
            plan_inputs = problem_inputs(planner, solved.X, solved.U, params, plan_refs)
            cases["plan 3d"] = (plan_inputs, None)
    return cases


@numba.njit(cache=False)
def _empty_call(fx, fu, lx, lu, lxx, lux, luu, vx, vxx, mu, K, k):  # noqa: ANN001, ANN202, PLR0913
    """A compiled function of the recursion's arguments that does nothing: its call's floor."""
    return 0.0, 0.0, True, 0.0


def measure(rounds: int = 5, index: int = 400, mu: float = 1e-3) -> dict[str, dict[str, float]]:
    """Per case, per pass in us, each net of its call's floor: ``compiled`` (minus an empty
    compiled function of the same arguments), ``xla_stored`` (minus an empty jitted call of the
    same inputs) and, for the MPC's cases, ``xla_stand_in`` (``ddp_parts``' whole
    ``backward_riccati`` pass minus its ``empty_call``); and ``steps``, ``unit_us``."""
    reference = ReferenceStep()
    out: dict[str, dict[str, float]] = {}
    for name, (inputs, window) in _cases(index).items():
        steps, n, m = inputs.fu.shape
        stored = stored_backward(inputs)
        stand_in = None
        if window is not None:
            calls = _problem_calls(window)
            stand_in = (calls["backward_riccati"], calls["empty_call"])
        recursion = compiled_recursion(n, m)
        K, k = np.empty((steps, m, n)), np.empty((steps, m))
        run_compiled(inputs, mu)  # compiles
        _empty_call(*inputs, mu, K, k)
        stored.call(mu)
        functions: dict[str, Callable[[], Any]] = {
            "compiled": lambda: recursion(*inputs, mu, K, k),  # noqa: B023
            "compiled_floor": lambda: _empty_call(*inputs, mu, K, k),  # noqa: B023
            "stored": lambda: stored.call(mu),  # noqa: B023
            "stored_floor": lambda: stored.floor(mu),  # noqa: B023
        }
        if stand_in is not None:
            functions["stand_in"], functions["stand_in_floor"] = stand_in
        med, unit = interleaved_rounds(functions, rounds, reference)
        out[name] = {
            "steps": float(steps),
            "compiled": med["compiled"] - med["compiled_floor"],
            "xla_stored": med["stored"] - med["stored_floor"],
            "unit_us": unit,
        }
        if stand_in is not None:
            out[name]["xla_stand_in"] = med["stand_in"] - med["stand_in_floor"]
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
    print("one Riccati recursion (2)-(5), per pass; per horizon step in brackets:")
    for name, f in measure(args.rounds, args.index).items():
        steps = f["steps"]
        parts = [
            f"{label} {f[key]:7.1f} us ({1e3 * f[key] / steps:4.0f} ns)"
            for key, label in (
                ("compiled", "compiled"),
                ("xla_stored", "xla stored"),
                ("xla_stand_in", "xla stand-ins"),
            )
            if key in f
        ]
        print(
            f"  {name:10s} N={int(steps):4d}  "
            + "  ".join(parts)
            + f"  (unit {f['unit_us']:.1f} us)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
