"""Differential dynamic programming (DDP) and iLQR in JAX, jit-compiled, for MPC reuse.

Problem
-------
Minimise over the control sequence ``U = (u_0, ..., u_{N-1})`` the cost

    J(U) = sum_{k=0}^{N-1} running(x_k, u_k, ref_k) + terminal(x_N, ref_N),       (1)
    x_{k+1} = dynamics(x_k, u_k, params),  x_0 given.

``dynamics`` is *discrete* (the caller wraps a continuous model, e.g. explicit Euler
``x + dt * f(x, u, params)`` as the authors did, docs/AUTHORS_CONFIG.md §3.1). ``refs`` is an array
or pytree whose leaves have a leading axis of length ``N + 1``: ``running`` sees ``refs[k]`` for
``k < N`` and ``terminal`` sees ``refs[N]``. A ``dt`` factor on the running cost is the caller's
business (put it inside ``running``).

Algorithm (Jacobson & Mayne 1970 DDP; regularisation and line search after Tassa, Erez &
Todorov 2012, "Synthesis and stabilization of complex behaviors through online trajectory
optimization", section II). All derivatives come from autodiff (``jax.jacfwd`` of the
dynamics, ``jax.grad``/``jax.hessian`` of the costs, ``jax.hessian`` of the dynamics for the
second-order terms), evaluated step by step inside the backward scan; a problem may give its
own exact ``running_derivatives`` and ``dynamics_derivatives`` instead (the WIPM's: closed
forms, and autodiff along only the inputs its model reads).

Backward pass (a reverse ``lax.scan``), with ``V'`` the value expansion at step ``k + 1``,
``V_x(N) = terminal_x``, ``V_xx(N) = terminal_xx``:

    Q_x  = l_x  + f_x^T V'_x                                                     (2)
    Q_u  = l_u  + f_u^T V'_x
    Q_xx = l_xx + f_x^T V'_xx f_x + [V'_x . f_xx]
    Q_ux = l_ux + f_u^T V'_xx f_x + [V'_x . f_ux]
    Q_uu = l_uu + f_u^T V'_xx f_u + [V'_x . f_uu]

The bracketed tensor terms (``V'_x`` contracted with the dynamics' output index) make it true
DDP; ``DDPConfig.second_order=False`` drops them, giving iLQR (Gauss-Newton on the dynamics,
what the authors' ``ddp.hpp`` does). Levenberg-Marquardt regularisation acts on ``Q_uu`` only
(the "control" regularisation of the authors' 46 ``ddp.hpp``; no ``V_xx`` / state
regularisation is used):

    k = -(Q_uu + mu I)^{-1} Q_u,   K = -(Q_uu + mu I)^{-1} Q_ux                   (3)

solved through a Cholesky factor. A Cholesky factor containing NaN (``Q_uu + mu I`` not positive
definite) at any step makes the pass fail; ``mu`` is then increased and the pass repeated
(inner ``lax.while_loop``). The value update uses the unregularised ``Q`` terms (Tassa 2012's
"improved value update", consistent with the step actually taken):

    V_x  = Q_x  + K^T Q_uu k + K^T Q_u + Q_ux^T k                                (4)
    V_xx = Q_xx + K^T Q_uu K + K^T Q_ux + Q_ux^T K          (its upper triangle, mirrored)

and the expected cost change of a step of size ``alpha`` is

    dV(alpha) = alpha sum_k k^T Q_u + alpha^2 / 2 sum_k k^T Q_uu k.              (5)

Unless ``DDPConfig.gradient_norm`` is False, the same scan also propagates the exact adjoint
``lam_k = l_x + f_x^T lam_{k+1}`` and so returns the true gradient
``dJ/du_k = l_u + f_u^T lam_{k+1}`` of (1), used by the optional
gradient-norm stop.

Forward pass / line search: for every ``alpha`` in ``DDPConfig.alphas`` (default
``1, 1/2, ..., 2^-10``), evaluated in parallel with ``jax.vmap``,

    x^_0 = x_0,  u^_k = u_k + alpha k_k + K_k (x^_k - x_k),  x^_{k+1} = f(x^_k, u^_k)   (6)

and the largest ``alpha`` is accepted whose actual reduction satisfies

    J - J(alpha) >= c * (-dV(alpha))   and   J - J(alpha) > 0,  J(alpha) finite,   (7)

with ``c = DDPConfig.line_search_c`` (default 1e-4, an Armijo-type test on the expected
reduction; Tassa 2012 accepts any positive ratio, the authors accept any cost decrease and
otherwise the last alpha).

Regularisation schedule (the authors' 46 ``ddp.hpp``, docs/AUTHORS_CONFIG.md §3.1), with ``f =
mu_factor`` and ``dmu`` starting at 1:

    increase (failed backward pass or failed line search):                        (8)
        dmu = max(dmu f, f);   mu = max(mu dmu, mu_min)
    decrease (accepted step):
        dmu = min(dmu / f, 1 / f);   mu = mu dmu;   mu = 0 if mu < mu_min

If an increase would exceed ``mu_max``, or cannot change ``mu`` (``mu = mu_min = 0``:
regularisation switched off, as in the authors' 13b which had none), the solve stops with
``converged = False``.

Iterations and stopping. A backward pass is done on the initial rollout before the loop. One
*iteration* is then one line search (6)-(7) followed by the backward pass at the resulting
trajectory (with any regularisation retries). So the gains returned always belong to the returned
``(X, U)``. After every backward pass the solve stops as converged if

    -dV(1) <= tolerance * |J| + abs_tolerance    or    max_k |dJ/du_k| <= grad_tolerance.  (9)

i.e. the predicted relative decrease of a full step is below ``tolerance``. Consequences: an
already-optimal warm start returns with ``iterations = 0``; a linear-quadratic problem with
``mu = 0`` takes exactly one iteration (the full Newton step is exact, and the backward pass at
the new trajectory predicts no further decrease). Note that (9) is evaluated at the current
``mu``: a large ``mu`` damps the predicted decrease, as in any Levenberg-Marquardt scheme.

jit. ``make_ddp_solver(dynamics, running, terminal, config)`` returns a ``DDPSolver`` whose
``jitted`` attribute is one ``jax.jit`` function ``(x0, U_init, params, refs) -> DDPResult``.
The horizon comes from the array shapes, so a new ``N`` (or new pytree structure/dtypes)
retraces and everything else reuses the compiled code: MPC calls it every tick with the
previous (shifted) controls as ``U_init`` (warm start). ``DDPSolver.solve`` (also
``__call__``) validates the inputs in Python first and raises ``ValueError``. ``ddp_solve`` is
the one-shot form; it caches solvers by ``(dynamics, running, terminal, config)`` identity.

Float64 is needed by DDP's convergence tests and the Riccati recursion: ``DDPSolver.solve``
traces, compiles and runs inside ``jax_setup.float64()`` (``jax.enable_x64``, thread-local),
whatever the process's global setting, and returns float64 arrays. ``solver.jitted`` is the
raw jitted function: call it inside that scope or inside other traced code that is (the MPC's
step is). The first solver of a process warns once if XLA's loop option could not be set
(``jax_setup.warn_if_loop_flag_missing``: JAX had started before ``import controllers``).

Speed (``controllers.optimizer.jax_setup``). Every loop (the rollouts, the backward scan with the
derivatives of each step computed inside it, the stage costs, the line search) is written so
that XLA:CPU compiles it into one kernel: the small products as broadcast sums (``_mv``,
``_mm``, ...) and ``Q_uu``'s Cholesky factor entry by entry (``_cholesky_solve``), since a
``dot`` or a LAPACK call inside a loop makes XLA dispatch every operation of every step
separately. The line search tries ``alpha = 1`` and then ``1/2`` alone first and the parallel
search over the rest only if both fail (the same accepted step). Each rollout (the warm
start's, every line search's) computes its stage costs in the same loop, which shares the
dynamics' arithmetic with the penalty's (measured: the MPC step 6-8 % faster, ``X`` and ``U``
bit for bit the same as with a separate cost loop). Results equal those of the plain
``@``/``cho_solve`` version to round-off (tests/test_ddp_speed.py).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from controllers.optimizer import jax_setup

__all__ = [
    "DDPConfig",
    "DDPResult",
    "DynamicsDerivatives",
    "RunningDerivatives",
    "DDPSolver",
    "ddp_solve",
    "make_ddp_solver",
    "riccati_step",
    "rollout",
    "trajectory_cost",
]

Array = jax.Array
PyTree = Any
Dynamics = Callable[[Array, Array, PyTree], Array]
RunningCost = Callable[[Array, Array, PyTree], Array]
TerminalCost = Callable[[Array, PyTree], Array]
# (x, u, ref) -> (l_x, l_u, l_xx, l_ux, l_uu) of the running cost at one step
RunningDerivatives = Callable[[Array, Array, PyTree], tuple[Array, Array, Array, Array, Array]]
# (x, u, params) -> (f_x, f_u) of the discrete dynamics at one step
DynamicsDerivatives = Callable[[Array, Array, PyTree], tuple[Array, Array]]


_ALPHAS_ALONE = 2
"""How many of the largest alphas the line search tries one at a time before the others in
parallel: the first is accepted in about three quarters of the MPC's line searches, and a
parallel search over all eleven cost about ten single rollouts."""


def _default_alphas() -> tuple[float, ...]:
    return tuple(2.0**-i for i in range(11))


@dataclass(frozen=True)
class DDPConfig:
    """Solver settings. Defaults and the authors' values (docs/AUTHORS_CONFIG.md §3).

    Attributes:
        max_iterations: Iteration budget (one iteration = line search + backward pass, see the
            module docstring). Authors: 50 for the offline DDP (15 in older versions) and 50 per
            MPC call (13b), with no other stopping rule. An MPC caller sets its own budget.
        tolerance: Stop when the predicted decrease of a full step, ``-dV(1)``, is at most
            ``tolerance * |J| + abs_tolerance``. Default 1e-8 (the authors have no tolerance;
            1e-8 is their unused box-QP "min relative improvement").
        abs_tolerance: Absolute part of that test, for costs whose optimum is near 0.
        grad_tolerance: Also stop when ``max |dJ/dU| <= grad_tolerance`` (exact gradient of the
            total cost from the adjoint recursion). 0 disables it.
        gradient_norm: True (default): the backward pass also runs the adjoint recursion for
            the exact gradient, ``DDPResult.grad_norm``. False: skipped, ``grad_norm`` is NaN,
            every other result the same (the MPC's and the plan's setting: they stop on other
            tests; it saves 6 to 8 % of the plan's time and about 5 % of the planar MPC
            step's). Needs ``grad_tolerance = 0``.
        second_order: True: DDP with the ``V_x . f_xx, f_ux, f_uu`` terms; False: iLQR (the
            authors' choice).
        mu_init: Initial ``Q_uu`` regularisation. Authors (46): 1.0. 13b had none (0).
        mu_factor: Schedule factor. Authors (46): 1.6.
        mu_min: Below this ``mu`` is set to 0 on decrease, and an increase starts from it.
            Authors (46): 1e-6. 0 together with ``mu_init = 0`` turns regularisation off.
        mu_max: Give up (``converged = False``) when ``mu`` would exceed it. Authors (46): 1e10.
        alphas: Line-search step sizes, tried in parallel, the largest acceptable one wins.
            Default ``2^0 ... 2^-10``. Authors: halve from 1 until the cost decreases, or accept
            the step anyway once alpha < 1e-4.
        line_search_c: Minimum ratio of actual to expected reduction (7). Default 1e-4.
        final_backward: True (default): the last iteration ends with its backward pass, so the
            returned gains belong to the returned ``(X, U)`` and (9) is tested there. False: an
            iteration that exhausts the budget skips it (a third of the work of a 2-iteration
            MPC solve, which uses only ``X``, ``U`` and the cost: those are unchanged); ``K``,
            ``k`` and ``grad_norm`` are then the previous pass's and ``converged`` is False
            unless (9) held earlier.
    """

    max_iterations: int = 50
    tolerance: float = 1e-8
    abs_tolerance: float = 0.0
    grad_tolerance: float = 0.0
    gradient_norm: bool = True
    second_order: bool = True
    mu_init: float = 1.0
    mu_factor: float = 1.6
    mu_min: float = 1e-6
    mu_max: float = 1e10
    alphas: tuple[float, ...] = _default_alphas()
    line_search_c: float = 1e-4
    final_backward: bool = True

    def __post_init__(self) -> None:
        if self.max_iterations < 0:
            raise ValueError(f"max_iterations must be >= 0, got {self.max_iterations}")
        if self.tolerance < 0 or self.abs_tolerance < 0 or self.grad_tolerance < 0:
            raise ValueError("tolerance, abs_tolerance and grad_tolerance must be >= 0")
        if self.grad_tolerance > 0 and not self.gradient_norm:
            raise ValueError(
                "grad_tolerance > 0 stops on the gradient: it needs gradient_norm=True "
                "(with --set, set gradient_norm first)"
            )
        if self.mu_factor <= 1.0:
            raise ValueError(f"mu_factor must be > 1, got {self.mu_factor}")
        if not 0.0 <= self.mu_min <= self.mu_max or self.mu_init < 0:
            raise ValueError("need 0 <= mu_min <= mu_max and mu_init >= 0")
        if len(self.alphas) == 0 or any(not 0.0 < a <= 1.0 for a in self.alphas):
            raise ValueError(f"alphas must be a non-empty tuple in (0, 1], got {self.alphas}")
        if list(self.alphas) != sorted(self.alphas, reverse=True):
            raise ValueError("alphas must be sorted in decreasing order")
        if not 0.0 <= self.line_search_c < 1.0:
            raise ValueError(f"line_search_c must be in [0, 1), got {self.line_search_c}")


class DDPResult(NamedTuple):
    """Solver output (all JAX arrays).

    Attributes:
        X: (N+1, n) states of the returned trajectory.
        U: (N, m) controls.
        K: (N, m, n) feedback gains of the last backward pass, which is taken at ``(X, U)``
            (unless the solve stopped on a failure, then NaN is possible; see ``converged``).
            The local policy is ``u = U[k] + K[k] (x - X[k])`` (plus ``k[k]`` if not converged).
        k: (N, m) feedforward terms of that pass (about 0 at convergence).
        cost_history: (max_iterations+1,) cost before the first iteration and after each one;
            entries past the stop repeat the final cost.
        mu_history: (max_iterations+1,) ``mu`` used by the backward pass after each iteration
            (entry 0: the initial pass, after any increases); entries past the stop repeat.
        iterations: Number of iterations done (0 if the warm start was already converged).
        converged: True iff the stopping test (9) held at the last backward pass.
        cost: Final cost ``J(U)``.
        grad_norm: ``max |dJ/dU|`` at the returned ``U`` (NaN if ``config.gradient_norm`` is
            False).
    """

    X: Array
    U: Array
    K: Array
    k: Array
    cost_history: Array
    mu_history: Array
    iterations: Array
    converged: Array
    cost: Array
    grad_norm: Array


def rollout(dynamics: Dynamics, x0: Array, U: Array, params: PyTree) -> Array:
    """States ``X`` (N+1, n) from ``x0`` under the controls ``U`` (N, m)."""

    def step(x: Array, u: Array) -> tuple[Array, Array]:
        x_next = dynamics(x, u, params)
        return x_next, x_next

    _, xs = jax.lax.scan(step, x0, U)
    return jnp.concatenate([x0[None], xs], axis=0)


def _head(refs: PyTree) -> PyTree:
    return jax.tree.map(lambda r: r[:-1], refs)


def _last(refs: PyTree) -> PyTree:
    return jax.tree.map(lambda r: r[-1], refs)


def trajectory_cost(
    running: RunningCost, terminal: TerminalCost, X: Array, U: Array, refs: PyTree
) -> Array:
    """Total cost (1): ``sum_k running(X[k], U[k], refs[k]) + terminal(X[N], refs[N])``."""
    # lax.map: one compiled loop over the steps (jax_setup) rather than an op per array kernel
    stage = jax.lax.map(lambda z: running(*z), (X[:-1], U, _head(refs)))
    return jnp.sum(stage) + terminal(X[-1], _last(refs))


# Small matrix products as broadcast products and sums: XLA:CPU keeps a ``dot`` as a library
# call, which also keeps a loop containing it out of the one-kernel compilation (jax_setup); the
# element-wise form fuses. The sums run over the same index in the same order as a dot would
# up to the rounding of the summation order.
def _mv(a: Array, v: Array) -> Array:
    """``a @ v`` for a matrix ``a`` and a vector ``v``."""
    return jnp.sum(a * v[None, :], axis=1)


def _tmv(a: Array, v: Array) -> Array:
    """``a.T @ v``."""
    return jnp.sum(a * v[:, None], axis=0)


def _mm(a: Array, b: Array) -> Array:
    """``a @ b`` for two matrices."""
    return jnp.sum(a[:, :, None] * b[None, :, :], axis=1)


def _tmm(a: Array, b: Array) -> Array:
    """``a.T @ b``."""
    return jnp.sum(a[:, :, None] * b[:, None, :], axis=0)


def _symmetrised(a: Array) -> Array:
    """``(a + a^T) / 2``, exactly symmetric; an exactly symmetric ``a`` comes back unchanged to
    the bit. The terminal Hessian (symmetric to round-off as autodiff makes it) goes through it
    before the recursion, as ``riccati_step`` takes ``V'_xx`` (its products read one
    triangle), and so do ``Q_xx`` and ``Q_uu``."""
    return 0.5 * (a + a.T)


def _mirrored_upper(a: Array) -> Array:
    """The symmetric matrix whose upper triangle (diagonal included) is ``a``'s.

    For a product known to be symmetric (``F' V F``, the new ``V_xx``): its lower triangle is
    then never read, so in the scalar code that the MPC's numba backend writes from the jaxpr
    (``controllers.optimizer.numba_ddp``) those products are dead and the compiler drops them
    (the 3-D backward pass about a quarter faster: 52.4 to 38.7 us). XLA computes both
    triangles and selects. The result is exactly symmetric."""
    upper = np.triu(np.ones(a.shape, dtype=bool))
    return jnp.where(upper, a, a.T)


def _contract(v: Array, t: Array) -> Array:
    """``sum_i v_i t[i]`` (the value gradient contracted with a dynamics Hessian's output
    index, the DDP terms of (2))."""
    return jnp.sum(v[:, None, None] * t, axis=0)


def _cholesky_solve(A: Array, B: Array) -> tuple[Array, Array]:
    """``A^-1 B`` for a small symmetric ``A`` (m x m) through its Cholesky factor ``A = L L^T``,
    written out entry by entry (``m`` is the control dimension: 1 or 2 here), and whether ``A``
    is positive definite (every pivot positive and finite).

    The same arithmetic as LAPACK's ``potrf``/``potrs`` for such sizes, but plain element-wise
    operations: a LAPACK custom call inside the backward ``lax.scan`` keeps XLA from compiling
    the scan into one kernel (jax_setup), which made every step ~20x slower.
    """
    m = A.shape[0]
    L: list[list[Array]] = [[jnp.zeros((), A.dtype)] * m for _ in range(m)]
    ok = jnp.array(True)
    for j in range(m):
        pivot = A[j, j] - sum((L[j][k] * L[j][k] for k in range(j)), jnp.zeros((), A.dtype))
        ok = ok & (pivot > 0.0)
        L[j][j] = jnp.sqrt(pivot)
        for i in range(j + 1, m):
            off = A[i, j] - sum((L[i][k] * L[j][k] for k in range(j)), jnp.zeros((), A.dtype))
            L[i][j] = off / L[j][j]
    y: list[Array] = []  # forward substitution L y = B, row by row
    for i in range(m):
        acc = B[i] - sum((L[i][k] * y[k] for k in range(i)), jnp.zeros_like(B[i]))
        y.append(acc / L[i][i])
    x: list[Array] = [jnp.zeros_like(B[0])] * m  # back substitution L^T x = y
    for i in reversed(range(m)):
        acc = y[i] - sum((L[k][i] * x[k] for k in range(i + 1, m)), jnp.zeros_like(B[i]))
        x[i] = acc / L[i][i]
    solution = jnp.stack(x)
    return solution, ok & jnp.all(jnp.isfinite(solution))


def riccati_step(
    derivatives: tuple[Array, ...], vx: Array, vxx: Array, mu: Array, second_order: bool
) -> tuple[Array, Array, Array, Array, Array, Array, Array]:
    """One step of the backward pass's recursion (2)-(5): from the stage derivatives
    ``(l_x, l_u, l_xx, l_ux, l_uu, f_x, f_u[, f_xx, f_ux, f_uu])`` and the next step's value
    expansion ``V'_x``, ``V'_xx`` (exactly symmetric: the products below read one triangle of
    what it makes), the value expansion here, the gains ``K``, ``k``, this step's terms of
    ``dV`` (5) and whether ``Q_uu + mu I`` was positive definite. A pure function: the
    backward scan runs it, and the MPC's numba backend (``controllers.optimizer.numba_ddp``)
    writes it out of its jaxpr as scalar code."""
    lx, lu, lxx, lux, luu, fx, fu = derivatives[:7]
    n, m = fx.shape[0], lu.shape[0]
    # (2) from F = [f_x f_u]: F^T V_x and F^T V_xx F in two products instead of five (each
    # entry the same sum in the same order as five products made it; XLA may fuse it
    # otherwise: the 3-D plan is bit-equal, planar within 3e-14; the recursion 11 % faster)
    F = jnp.concatenate([fx, fu], axis=1)
    q_lin = _tmv(F, vx)
    # [[f_x' V f_x, f_x' V f_u], [f_u' V f_x, f_u' V f_u]], symmetric: its upper triangle
    quad = _mirrored_upper(_tmm(F, _mm(vxx, F)))
    qx = lx + q_lin[:n]
    qu = lu + q_lin[n:]
    qxx = lxx + quad[:n, :n]
    qux = lux + quad[n:, :n]
    quu = luu + quad[n:, n:]
    if second_order:
        fxx, fux, fuu = derivatives[7:]
        qxx = qxx + _contract(vx, fxx)
        qux = qux + _contract(vx, fux)
        quu = quu + _contract(vx, fuu)
    qxx = _symmetrised(qxx)
    quu = _symmetrised(quu)
    eye = jnp.eye(m, dtype=quu.dtype)
    sol, ok = _cholesky_solve(quu + mu * eye, jnp.concatenate([qu[:, None], qux], 1))
    k, K = -sol[:, 0], -sol[:, 1:]
    quu_k = _mv(quu, k)
    vx_new = qx + _tmv(K, quu_k) + _tmv(K, qu) + _tmv(qux, k)
    cross = _tmm(K, qux)  # K' Q_ux; Q_ux' K is its transpose (the same products)
    # (4), symmetric: its upper triangle
    vxx_new = _mirrored_upper(qxx + _tmm(K, _mm(quu, K)) + cross + cross.T)
    return vx_new, vxx_new, K, k, jnp.sum(k * qu), 0.5 * jnp.sum(k * quu_k), ok


class _Backward(NamedTuple):
    K: Array
    k: Array
    dv1: Array  # sum k^T Q_u
    dv2: Array  # 1/2 sum k^T Q_uu k
    grad_norm: Array
    ok: Array


class _LoopState(NamedTuple):
    X: Array
    U: Array
    cost: Array
    bp: _Backward
    mu: Array
    dmu: Array
    iteration: Array
    started: Array
    done: Array
    converged: Array
    cost_history: Array
    mu_history: Array


class DDPSolver:
    """A compiled DDP solver for fixed functions and config.

    ``solver(x0, U_init, params, refs)`` (= ``solver.solve``) validates the inputs and calls
    ``solver.jitted``, the raw ``jax.jit`` function (usable inside other traced code).
    ``trace_count`` counts how often the solver body has been traced (one per new shape).
    """

    def __init__(
        self,
        dynamics: Dynamics,
        running: RunningCost,
        terminal: TerminalCost,
        config: DDPConfig,
        running_derivatives: RunningDerivatives | None = None,
        dynamics_derivatives: DynamicsDerivatives | None = None,
    ) -> None:
        self.dynamics = dynamics
        self.running = running
        self.terminal = terminal
        self.config = config
        self.running_derivatives = running_derivatives
        self.dynamics_derivatives = dynamics_derivatives
        self.trace_count = 0
        jax_setup.warn_if_loop_flag_missing()  # once per process, if JAX started without it
        self.jitted: Callable[[Array, Array, PyTree, PyTree], DDPResult] = jax.jit(self._solve)

    def __call__(self, x0: Any, U_init: Any, params: PyTree, refs: PyTree) -> DDPResult:
        return self.solve(x0, U_init, params, refs)

    def solve(self, x0: Any, U_init: Any, params: PyTree, refs: PyTree) -> DDPResult:
        """Validate (outside jit; raises ValueError) and solve, warm-started from ``U_init``,
        in float64 (``jax_setup.float64``)."""
        x0_np = np.asarray(x0, dtype=np.float64)
        U_np = np.asarray(U_init, dtype=np.float64)
        if x0_np.ndim != 1 or x0_np.size == 0:
            raise ValueError(f"x0 must be a non-empty 1-D state vector, got shape {x0_np.shape}")
        if not np.all(np.isfinite(x0_np)):
            raise ValueError(f"x0 contains non-finite values: {x0_np}")
        if U_np.ndim != 2 or U_np.shape[0] < 1 or U_np.shape[1] < 1:
            raise ValueError(
                f"U_init must have shape (N, m) with N >= 1 and m >= 1, got {U_np.shape}"
            )
        if not np.all(np.isfinite(U_np)):
            raise ValueError("U_init contains non-finite values")
        horizon = U_np.shape[0]
        leaves = jax.tree.leaves(refs)
        if not leaves:
            raise ValueError("refs must contain at least one array with leading axis N+1")
        for leaf in leaves:
            shape = np.shape(leaf)
            if len(shape) == 0 or shape[0] != horizon + 1:
                raise ValueError(
                    f"every refs leaf needs a leading axis of length N+1 = {horizon + 1} "
                    f"(U_init has N = {horizon}), got a leaf of shape {shape}"
                )
            arr = np.asarray(leaf)
            if np.issubdtype(arr.dtype, np.floating) and not np.all(np.isfinite(arr)):
                raise ValueError("refs contains non-finite values")
        with jax_setup.float64():
            return self.jitted(x0_np, U_np, params, refs)

    # ---------------------------------------------------------------- traced internals
    def _check_signatures(self, x0: Array, U: Array, params: PyTree, refs: PyTree) -> None:
        n = x0.shape[0]
        x_next = jax.eval_shape(self.dynamics, x0, U[0], params)
        if getattr(x_next, "shape", None) != (n,):
            raise ValueError(
                f"dynamics(x, u, params) must return shape ({n},) like x0, got "
                f"{getattr(x_next, 'shape', type(x_next))}"
            )
        if self.dynamics_derivatives is not None:
            fx, fu = jax.eval_shape(self.dynamics_derivatives, x0, U[0], params)
            m = U.shape[1]
            if (fx.shape, fu.shape) != ((n, n), (n, m)):
                raise ValueError(
                    f"dynamics_derivatives(x, u, params) must return (f_x, f_u) of shapes "
                    f"({n}, {n}) and ({n}, {m}), got {fx.shape} and {fu.shape}"
                )
        ref0 = jax.tree.map(lambda r: r[0], refs)
        stage = jax.eval_shape(self.running, x0, U[0], ref0)
        if getattr(stage, "shape", None) != ():
            raise ValueError("running(x, u, ref) must return a scalar")
        final = jax.eval_shape(self.terminal, x0, ref0)
        if getattr(final, "shape", None) != ():
            raise ValueError("terminal(x, ref) must return a scalar")

    def _stage_derivatives(self, x: Array, u: Array, r: PyTree, params: PyTree) -> tuple:
        """``(l_x, l_u, l_xx, l_ux, l_uu, f_x, f_u[, f_xx, f_ux, f_uu])`` at one step."""
        dyn, run = self.dynamics, self.running
        if self.dynamics_derivatives is not None:
            fx, fu = self.dynamics_derivatives(x, u, params)
        else:
            fx, fu = jax.jacfwd(dyn, argnums=(0, 1))(x, u, params)
        if self.running_derivatives is not None:
            lx, lu, lxx, lux, luu = self.running_derivatives(x, u, r)
        else:
            lx, lu = jax.grad(run, argnums=(0, 1))(x, u, r)
            (lxx, _), (lux, luu) = jax.hessian(run, argnums=(0, 1))(x, u, r)
        out: tuple[Array, ...] = (lx, lu, lxx, lux, luu, fx, fu)
        if self.config.second_order:
            (fxx, _), (fux, fuu) = jax.hessian(dyn, argnums=(0, 1))(x, u, params)
            out = (*out, fxx, fux, fuu)
        return out

    def _backward(self, X: Array, U: Array, params: PyTree, refs: PyTree, mu: Array) -> _Backward:
        """Backward pass (2)-(5) along ``(X, U)``, the derivatives of each step computed inside
        the scan (one compiled loop, no (N, n, n) arrays of derivatives in memory)."""
        second = self.config.second_order
        gradient = self.config.gradient_norm

        def step(carry: tuple[Array, ...], z: tuple[Array, ...]) -> tuple[tuple, tuple]:
            vx, vxx, lam, dv1, dv2, ok, gmax = carry
            derivatives = self._stage_derivatives(*z, params)
            lx, lu, lxx, lux, luu, fx, fu = derivatives[:7]
            vx_new, vxx_new, K, k, dv1_k, dv2_k, step_ok = riccati_step(
                derivatives, vx, vxx, mu, second
            )
            if gradient:
                grad_u = lu + _tmv(fu, lam)
                lam_new = lx + _tmv(fx, lam)
                gmax = jnp.maximum(gmax, jnp.max(jnp.abs(grad_u)))
            else:
                lam_new = lam
            carry = (
                vx_new,
                vxx_new,
                lam_new,
                dv1 + dv1_k,
                dv2 + dv2_k,
                ok & step_ok,
                gmax,
            )
            return carry, (K, k)

        xN, refN = X[-1], _last(refs)
        vx = jax.grad(self.terminal)(xN, refN)
        vxx = _symmetrised(jax.hessian(self.terminal)(xN, refN))
        zero = jnp.zeros((), vx.dtype)
        init = (vx, vxx, vx, zero, zero, jnp.array(True), zero)
        zs = (X[:-1], U, _head(refs))
        (_, _, _, dv1, dv2, ok, gmax), (K, k) = jax.lax.scan(step, init, zs, reverse=True)
        ok = ok & jnp.isfinite(dv1) & jnp.isfinite(dv2)
        grad_norm = gmax if gradient else jnp.full((), jnp.nan, gmax.dtype)
        return _Backward(K=K, k=k, dv1=dv1, dv2=dv2, grad_norm=grad_norm, ok=ok)

    def _increase(self, mu: Array, dmu: Array) -> tuple[Array, Array]:
        f = self.config.mu_factor
        dmu = jnp.maximum(dmu * f, f)
        return jnp.maximum(mu * dmu, self.config.mu_min), dmu

    def _decrease(self, mu: Array, dmu: Array) -> tuple[Array, Array]:
        f = self.config.mu_factor
        dmu = jnp.minimum(dmu / f, 1.0 / f)
        mu = mu * dmu
        return jnp.where(mu < self.config.mu_min, 0.0, mu), dmu

    def _backward_regularised(
        self, X: Array, U: Array, params: PyTree, refs: PyTree, mu: Array, dmu: Array
    ) -> tuple[_Backward, Array, Array]:
        """Backward pass, increasing mu until Q_uu + mu I is PD everywhere (8).

        One ``_backward`` in the loop body (so it is compiled once). Returns the last pass (its
        ``ok`` is False if mu hit ``mu_max`` or could not grow) and the mu it used.
        """
        n, (horizon, m) = X.shape[1], U.shape
        zero = jnp.zeros((), X.dtype)
        placeholder = _Backward(
            K=jnp.zeros((horizon, m, n), X.dtype),
            k=jnp.zeros((horizon, m), X.dtype),
            dv1=zero,
            dv2=zero,
            grad_norm=zero,
            ok=jnp.array(False),
        )

        def cond(s: tuple) -> Array:
            bp_, _, _, give_up = s
            return ~bp_.ok & ~give_up

        def body(s: tuple) -> tuple:
            _, mu_, dmu_, _ = s
            bp_ = self._backward(X, U, params, refs, mu_)
            mu2, dmu2 = self._increase(mu_, dmu_)
            give_up = ~bp_.ok & ((mu2 > self.config.mu_max) | (mu2 <= mu_))
            advance = ~bp_.ok & ~give_up
            return (
                bp_,
                jnp.where(advance, mu2, mu_),
                jnp.where(advance, dmu2, dmu_),
                give_up,
            )

        bp, mu, dmu, _ = jax.lax.while_loop(cond, body, (placeholder, mu, dmu, jnp.array(False)))
        return bp, mu, dmu

    def _converged(self, bp: _Backward, cost: Array) -> Array:
        cfg = self.config
        predicted = -(bp.dv1 + bp.dv2)
        small_step = predicted <= cfg.tolerance * jnp.abs(cost) + cfg.abs_tolerance
        small_grad = bp.grad_norm <= cfg.grad_tolerance
        return bp.ok & (small_step | small_grad)

    def _solve(self, x0: Array, U_init: Array, params: PyTree, refs: PyTree) -> DDPResult:
        self.trace_count += 1
        cfg = self.config
        x0 = jnp.asarray(x0, dtype=jnp.float64)
        U0 = jnp.asarray(U_init, dtype=jnp.float64)
        self._check_signatures(x0, U0, params, refs)
        dyn, run, term = self.dynamics, self.running, self.terminal

        alphas = jnp.asarray(cfg.alphas, dtype=jnp.float64)

        def with_cost(xs: Array, us: Array, stages: Array) -> tuple[Array, Array, Array]:
            """The trajectory and its cost (1) from the stage costs of the scan that made it
            (the sum as ``trajectory_cost`` takes it)."""
            X = jnp.concatenate([x0[None], xs], axis=0)
            return X, us, jnp.sum(stages) + term(X[-1], _last(refs))

        def forward(X: Array, U: Array, bp: _Backward, alpha: Array) -> tuple[Array, Array, Array]:
            """(6) and the new trajectory's cost, its stage costs in the same loop (the running
            cost shares the dynamics' arithmetic: one loop instead of two)."""

            def step(x: Array, z: tuple[Array, ...]) -> tuple[Array, tuple[Array, ...]]:
                x_ref, u_ref, K, k, ref = z
                u = u_ref + alpha * k + _mv(K, x - x_ref)
                x_next = dyn(x, u, params)
                return x_next, (x_next, u, run(x, u, ref))

            _, (xs, us, stages) = jax.lax.scan(step, x0, (X[:-1], U, bp.K, bp.k, _head(refs)))
            return with_cost(xs, us, stages)

        def initial_rollout(U: Array) -> tuple[Array, Array, Array]:
            """``rollout`` of the warm start and its cost, in one loop."""

            def step(x: Array, z: tuple[Array, ...]) -> tuple[Array, tuple[Array, ...]]:
                u, ref = z
                x_next = dyn(x, u, params)
                return x_next, (x_next, run(x, u, ref))

            _, (xs, stages) = jax.lax.scan(step, x0, (U, _head(refs)))
            return with_cost(xs, U, stages)

        # The warm start's rollout and cost are the iteration loop's first pass (``initial``),
        # not a loop of their own before it: XLA:CPU runs loops nested in one loop as one
        # kernel, while every top-level loop of a call costs tens of microseconds on its own
        # (measured: four rollouts as four loops 3x the time of the same four nested in one).
        # The placeholders below are overwritten by that first pass.
        mu = jnp.asarray(cfg.mu_init, dtype=jnp.float64)
        length = cfg.max_iterations + 1
        n, (horizon, m) = x0.shape[0], U0.shape
        zero = jnp.zeros((), jnp.float64)
        state = _LoopState(
            X=jnp.zeros((horizon + 1, n), jnp.float64),
            U=U0,
            cost=zero,
            bp=_Backward(
                K=jnp.zeros((horizon, m, n)),
                k=jnp.zeros((horizon, m)),
                dv1=zero,
                dv2=zero,
                grad_norm=zero,
                ok=jnp.array(False),
            ),
            mu=mu,
            dmu=jnp.asarray(1.0, dtype=jnp.float64),
            iteration=jnp.asarray(0),
            started=jnp.array(False),
            done=jnp.array(False),
            converged=jnp.array(False),
            cost_history=jnp.zeros((length,), jnp.float64),
            mu_history=jnp.full((length,), mu),
        )

        def acceptable(s: _LoopState, cost: Array, alpha: Array) -> Array:
            """Test (7) of a candidate's cost for step size ``alpha``."""
            actual = s.cost - cost
            expected = -(alpha * s.bp.dv1 + alpha**2 * s.bp.dv2)
            return jnp.isfinite(cost) & (actual > 0) & (actual >= cfg.line_search_c * expected)

        alone = min(_ALPHAS_ALONE, len(cfg.alphas))

        def search_rest(s: _LoopState) -> tuple[Array, Array, Array, Array]:
            """The alphas after the first ``alone`` in parallel; the largest acceptable one
            (X, U, cost, accepted)."""
            rest = alphas[alone:]
            Xs, Us, costs = jax.vmap(lambda a: forward(s.X, s.U, s.bp, a))(rest)
            good = acceptable(s, costs, rest)
            best = jnp.argmax(good)
            return Xs[best], Us[best], costs[best], jnp.any(good)

        def try_alone(s: _LoopState, i: int) -> tuple[Array, Array, Array, Array]:
            """alphas[i] alone; if it is not acceptable, the next (alone, then in parallel)."""
            if i == alone:
                if alone == len(cfg.alphas):
                    return s.X, s.U, s.cost, jnp.array(False)
                return search_rest(s)
            X1, U1, cost1 = forward(s.X, s.U, s.bp, alphas[i])
            return jax.lax.cond(
                acceptable(s, cost1, alphas[i]),
                lambda: (X1, U1, cost1, jnp.array(True)),
                lambda: try_alone(s, i + 1),
            )

        def line_search(s: _LoopState) -> tuple[Array, Array, Array, Array, Array, Array]:
            """(6)-(7); returns X, U, cost, mu, dmu for the next backward pass and `stuck`.

            The largest alphas are tried one at a time first (``_ALPHAS_ALONE`` of them): the
            first is usually accepted, and the first acceptable one is the answer of a parallel
            search too (the largest acceptable alpha), at a fraction of its cost. Only then are
            the others tried in parallel."""
            X_new, U_new, cost_new, accepted = try_alone(s, 0)
            mu_dn, dmu_dn = self._decrease(s.mu, s.dmu)
            mu_up, dmu_up = self._increase(s.mu, s.dmu)
            # A failed line search that cannot raise mu any further ends the solve.
            stuck = ~accepted & ((mu_up > cfg.mu_max) | (mu_up <= s.mu))
            return (
                jnp.where(accepted, X_new, s.X),
                jnp.where(accepted, U_new, s.U),
                jnp.where(accepted, cost_new, s.cost),
                jnp.where(accepted, mu_dn, jnp.where(stuck, s.mu, mu_up)),
                jnp.where(accepted, dmu_dn, jnp.where(stuck, s.dmu, dmu_up)),
                stuck,
            )

        def initial(s: _LoopState) -> tuple[Array, Array, Array, Array, Array, Array]:
            X, U, cost = initial_rollout(s.U)
            return X, U, cost, s.mu, s.dmu, jnp.array(False)

        def cond(s: _LoopState) -> Array:
            return ~s.started | (~s.done & (s.iteration < cfg.max_iterations))

        def body(s: _LoopState) -> _LoopState:
            # The first pass only does the backward pass on the initial rollout.
            X_new, U_new, cost_new, mu_new, dmu_new, stuck = jax.lax.cond(
                s.started, line_search, initial, s
            )

            def redo() -> tuple[_Backward, Array, Array]:
                return self._backward_regularised(X_new, U_new, params, refs, mu_new, dmu_new)

            def keep() -> tuple[_Backward, Array, Array]:
                return s.bp._replace(ok=jnp.array(False)), mu_new, dmu_new

            it = s.iteration + s.started.astype(s.iteration.dtype)
            last = (it >= cfg.max_iterations) & s.started & (not cfg.final_backward)
            bp_new, mu_new, dmu_new = jax.lax.cond(stuck | last, keep, redo)
            conv = self._converged(bp_new, cost_new)
            tail = jnp.arange(length) >= it
            return _LoopState(
                X=X_new,
                U=U_new,
                cost=cost_new,
                bp=bp_new,
                mu=mu_new,
                dmu=dmu_new,
                iteration=it,
                started=jnp.array(True),
                done=conv | ~bp_new.ok,
                converged=conv,
                cost_history=jnp.where(tail, cost_new, s.cost_history),
                mu_history=jnp.where(tail, mu_new, s.mu_history),
            )

        final = jax.lax.while_loop(cond, body, state)
        return DDPResult(
            X=final.X,
            U=final.U,
            K=final.bp.K,
            k=final.bp.k,
            cost_history=final.cost_history,
            mu_history=final.mu_history,
            iterations=final.iteration,
            converged=final.converged,
            cost=final.cost,
            grad_norm=final.bp.grad_norm,
        )


def make_ddp_solver(
    dynamics: Dynamics,
    running: RunningCost,
    terminal: TerminalCost,
    config: DDPConfig | None = None,
    running_derivatives: RunningDerivatives | None = None,
    dynamics_derivatives: DynamicsDerivatives | None = None,
) -> DDPSolver:
    """Build a solver; call it as ``solver(x0, U_init, params, refs) -> DDPResult``.

    ``running_derivatives(x, u, ref) -> (l_x, l_u, l_xx, l_ux, l_uu)``, if given, replaces the
    autodiff gradient and Hessian of ``running`` (it must be exact: a cheaper closed form).
    ``dynamics_derivatives(x, u, params) -> (f_x, f_u)``, if given, replaces ``jax.jacfwd`` of
    ``dynamics`` (exact too: autodiff along fewer directions, for example).

    One compilation per distinct input shape (horizon) and pytree structure; reuse the same
    solver object in an MPC loop so that every call after the first runs compiled code.
    """
    config = config if config is not None else DDPConfig()
    return DDPSolver(dynamics, running, terminal, config, running_derivatives, dynamics_derivatives)


@functools.lru_cache(maxsize=32)
def _cached_solver(
    dynamics: Dynamics, running: RunningCost, terminal: TerminalCost, config: DDPConfig
) -> DDPSolver:
    return DDPSolver(dynamics, running, terminal, config)


def ddp_solve(
    dynamics: Dynamics,
    running: RunningCost,
    terminal: TerminalCost,
    x0: Any,
    U_init: Any,
    params: PyTree,
    refs: PyTree,
    config: DDPConfig | None = None,
) -> DDPResult:
    """One-shot solve (validated). Solvers are cached by function identity and config, so
    repeated calls with the same (module-level, not freshly created lambda) functions reuse the
    compiled code."""
    solver = _cached_solver(dynamics, running, terminal, config or DDPConfig())
    return solver.solve(x0, U_init, params, refs)
