"""A plain NumPy iLQR, the peer the ``wip-bench solvers`` benchmark compares the JAX DDP with.

It solves the same problem as ``controllers.optimizer.ddp`` with ``second_order=False`` (iLQR) and
the same algorithm, step for step, so that both take the same iterations and reach the same
optimum: the backward pass (Riccati recursion with Levenberg-Marquardt regularisation on
``Q_uu`` only, Tassa 2012's improved value update), the same ``mu`` schedule, a line search
over the same step sizes (tried one at a time from the largest, stopping at the first
acceptable one: the same choice the JAX solver makes in parallel) with the same Armijo-type
test, and the same stopping test ``-dV(1) <= tolerance |J| + abs_tolerance``.

What is NumPy and what is not. The model derivatives (``f_x, f_u, l_x, l_u, l_xx, l_ux, l_uu``
along the trajectory, and the terminal gradient and Hessian) come from the SAME JAX functions
(autodiff of the problem's dynamics and costs), one jitted, vmapped call per iteration whose
output is converted to NumPy. The single-step dynamics the forward rollout needs is the same
JAX function, jitted, called once per step from the Python loop; the trajectory cost of a
candidate is one jitted call. Everything else (the backward recursion, the rollouts, the line
search, the regularisation schedule, the bookkeeping) is plain Python loops over NumPy arrays.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from numpy.typing import NDArray

from controllers.optimizer.ddp import DDPConfig, trajectory_cost

__all__ = ["NumpyILQR", "NumpyILQRResult"]

FloatArray = NDArray[np.float64]
PyTree = Any


@dataclass(frozen=True)
class NumpyILQRResult:
    """Solver output (NumPy), the fields of ``controllers.optimizer.ddp.DDPResult`` the benchmark
    uses.

    Attributes:
        X: (N+1, n) states. U: (N, m) controls. K: (N, m, n) gains. k: (N, m) feedforward.
        cost: final cost. initial_cost: cost of the warm start.
        iterations: iterations done (line search + backward pass each).
        converged: the stopping test held at the last backward pass.
    """

    X: FloatArray
    U: FloatArray
    K: FloatArray
    k: FloatArray
    cost: float
    initial_cost: float
    iterations: int
    converged: bool


@dataclass
class _Backward:
    K: FloatArray
    k: FloatArray
    dv1: float
    dv2: float
    ok: bool


class NumpyILQR:
    """iLQR in NumPy loops for ``dynamics(x, u, params)``, ``running(x, u, ref)``,
    ``terminal(x, ref)`` (the ``controllers.optimizer.ddp`` conventions; ``refs`` leaves have a
    leading axis of ``N + 1``). Call as ``solver(x0, U_init, params, refs)``.

    The JAX helpers are compiled on first use for each horizon (as with the JAX solver).
    """

    def __init__(
        self,
        dynamics: Callable[..., Any],
        running: Callable[..., Any],
        terminal: Callable[..., Any],
        config: DDPConfig,
    ) -> None:
        if config.second_order:
            raise ValueError("NumpyILQR is iLQR only: use a DDPConfig with second_order=False")
        if config.grad_tolerance > 0:
            raise ValueError("NumpyILQR does not implement the gradient-norm stop")
        self.config = config
        self.alphas = tuple(float(a) for a in config.alphas)

        self._dynamics = dynamics
        self._steps: dict[Any, tuple[Callable[..., Any], Callable[..., Any]]] = {}

        def derivatives(X: jax.Array, U: jax.Array, params: PyTree, refs: PyTree) -> tuple:
            def stage(x: jax.Array, u: jax.Array, r: PyTree) -> tuple:
                fx, fu = jax.jacfwd(dynamics, argnums=(0, 1))(x, u, params)
                lx, lu = jax.grad(running, argnums=(0, 1))(x, u, r)
                (lxx, _), (lux, luu) = jax.hessian(running, argnums=(0, 1))(x, u, r)
                return lx, lu, lxx, lux, luu, fx, fu

            head = jax.tree.map(lambda a: a[:-1], refs)
            last = jax.tree.map(lambda a: a[-1], refs)
            parts = jax.vmap(stage)(X[:-1], U, head)
            vx = jax.grad(terminal)(X[-1], last)
            vxx = jax.hessian(terminal)(X[-1], last)
            return (*parts, vx, vxx)

        def cost(X: jax.Array, U: jax.Array, refs: PyTree) -> jax.Array:
            return trajectory_cost(running, terminal, X, U, refs)

        self._derivatives = jax.jit(derivatives)
        self._cost = jax.jit(cost)

    def __call__(self, x0: Any, U_init: Any, params: PyTree, refs: PyTree) -> NumpyILQRResult:
        return self.solve(x0, U_init, params, refs)

    # ------------------------------------------------------------------ pieces
    def _step_for(self, params: PyTree) -> tuple[FloatArray, Callable[..., Any]]:
        """The parameters as one flat vector and the jitted ``step(x, u, flat)`` (one per
        parameter structure: fewer arguments to dispatch per call in the rollout loop)."""
        leaves, treedef = jax.tree.flatten(params)
        key = (treedef, tuple(np.shape(leaf) for leaf in leaves))
        flat_jax, unravel = ravel_pytree(params)
        if key not in self._steps:
            dynamics = self._dynamics

            def step(x: jax.Array, u: jax.Array, flat: jax.Array) -> jax.Array:
                return dynamics(x, u, unravel(flat))

            self._steps[key] = (unravel, jax.jit(step))
        return np.asarray(flat_jax), self._steps[key][1]

    def _rollout(
        self,
        x0: FloatArray,
        U: FloatArray,
        flat: FloatArray,
        step: Callable[..., Any],
        X_ref: FloatArray | None = None,
        bp: _Backward | None = None,
        alpha: float = 0.0,
    ) -> tuple[FloatArray, FloatArray]:
        """Open loop (``bp`` None) or the closed-loop forward pass (6) of the DDP docstring."""
        horizon = U.shape[0]
        X = np.empty((horizon + 1, x0.shape[0]))
        U_new = np.empty_like(U)
        X[0] = x0
        for i in range(horizon):
            if bp is None or X_ref is None:
                u = U[i]
            else:
                u = U[i] + alpha * bp.k[i] + bp.K[i] @ (X[i] - X_ref[i])
            U_new[i] = u
            X[i + 1] = np.asarray(step(X[i], u, flat))
        return X, U_new

    def _total_cost(self, X: FloatArray, U: FloatArray, refs: PyTree) -> float:
        return float(self._cost(X, U, refs))

    def _backward(self, d: tuple[FloatArray, ...], mu: float) -> _Backward:
        lx, lu, lxx, lux, luu, fx, fu, vx, vxx = d
        horizon, m = lu.shape
        n = lx.shape[1]
        eye = np.eye(m)
        K = np.zeros((horizon, m, n))
        k = np.zeros((horizon, m))
        dv1 = 0.0
        dv2 = 0.0
        for i in range(horizon - 1, -1, -1):
            fx_i, fu_i = fx[i], fu[i]
            fxT_vxx = fx_i.T @ vxx
            fuT_vxx = fu_i.T @ vxx
            qx = lx[i] + fx_i.T @ vx
            qu = lu[i] + fu_i.T @ vx
            qxx = lxx[i] + fxT_vxx @ fx_i
            qux = lux[i] + fuT_vxx @ fx_i
            quu = luu[i] + fuT_vxx @ fu_i
            qxx = 0.5 * (qxx + qxx.T)
            quu = 0.5 * (quu + quu.T)
            try:
                chol = np.linalg.cholesky(quu + mu * eye)
            except np.linalg.LinAlgError:
                return _Backward(K=K, k=k, dv1=np.nan, dv2=np.nan, ok=False)
            rhs = np.concatenate([qu[:, None], qux], axis=1)
            sol = np.linalg.solve(chol.T, np.linalg.solve(chol, rhs))
            k_i, K_i = -sol[:, 0], -sol[:, 1:]
            quu_k = quu @ k_i
            vx = qx + K_i.T @ quu_k + K_i.T @ qu + qux.T @ k_i
            vxx = qxx + K_i.T @ quu @ K_i + K_i.T @ qux + qux.T @ K_i
            vxx = 0.5 * (vxx + vxx.T)
            dv1 += float(k_i @ qu)
            dv2 += 0.5 * float(k_i @ quu_k)
            K[i], k[i] = K_i, k_i
        ok = bool(np.isfinite(dv1) and np.isfinite(dv2))
        return _Backward(K=K, k=k, dv1=dv1, dv2=dv2, ok=ok)

    def _increase(self, mu: float, dmu: float) -> tuple[float, float]:
        f = self.config.mu_factor
        dmu = max(dmu * f, f)
        return max(mu * dmu, self.config.mu_min), dmu

    def _decrease(self, mu: float, dmu: float) -> tuple[float, float]:
        f = self.config.mu_factor
        dmu = min(dmu / f, 1.0 / f)
        mu = mu * dmu
        return (0.0 if mu < self.config.mu_min else mu), dmu

    def _backward_regularised(
        self, d: tuple[FloatArray, ...], mu: float, dmu: float
    ) -> tuple[_Backward, float, float]:
        while True:
            bp = self._backward(d, mu)
            if bp.ok:
                return bp, mu, dmu
            mu_up, dmu_up = self._increase(mu, dmu)
            if mu_up > self.config.mu_max or mu_up <= mu:
                return bp, mu, dmu
            mu, dmu = mu_up, dmu_up

    def _converged(self, bp: _Backward, cost: float) -> bool:
        cfg = self.config
        predicted = -(bp.dv1 + bp.dv2)
        return bp.ok and predicted <= cfg.tolerance * abs(cost) + cfg.abs_tolerance

    # ------------------------------------------------------------------ solve
    def solve(self, x0: Any, U_init: Any, params: PyTree, refs: PyTree) -> NumpyILQRResult:
        """Solve from ``x0``, warm-started from ``U_init`` (see the module docstring)."""
        cfg = self.config
        x0 = np.asarray(x0, dtype=np.float64)
        U = np.array(U_init, dtype=np.float64)
        flat, step = self._step_for(params)

        def derivatives(X: FloatArray, U: FloatArray) -> tuple[FloatArray, ...]:
            out = self._derivatives(jnp.asarray(X), jnp.asarray(U), params, refs)
            return tuple(np.asarray(a) for a in out)

        X, _ = self._rollout(x0, U, flat, step)
        cost = self._total_cost(X, U, refs)
        initial_cost = cost
        mu, dmu = float(cfg.mu_init), 1.0
        d = derivatives(X, U)
        bp, mu, dmu = self._backward_regularised(d, mu, dmu)
        converged = self._converged(bp, cost)
        done = converged or not bp.ok
        iterations = 0
        while not done and iterations < cfg.max_iterations:
            accepted = False
            for alpha in self.alphas:
                X_new, U_new = self._rollout(x0, U, flat, step, X, bp, alpha)
                cost_new = self._total_cost(X_new, U_new, refs)
                actual = cost - cost_new
                expected = -(alpha * bp.dv1 + alpha**2 * bp.dv2)
                if np.isfinite(cost_new) and actual > 0 and actual >= cfg.line_search_c * expected:
                    accepted = True
                    break
            iterations += 1
            if accepted:
                X, U, cost = X_new, U_new, cost_new
                mu, dmu = self._decrease(mu, dmu)
                d = derivatives(X, U)
            else:
                mu_up, dmu_up = self._increase(mu, dmu)
                if mu_up > cfg.mu_max or mu_up <= mu:  # stuck: cannot regularise further
                    bp.ok = False
                    converged = False
                    break
                mu, dmu = mu_up, dmu_up  # same trajectory: the derivatives are unchanged
            bp, mu, dmu = self._backward_regularised(d, mu, dmu)
            converged = self._converged(bp, cost)
            done = converged or not bp.ok
        return NumpyILQRResult(
            X=X,
            U=U,
            K=bp.K,
            k=bp.k,
            cost=cost,
            initial_cost=initial_cost,
            iterations=iterations,
            converged=converged,
        )
