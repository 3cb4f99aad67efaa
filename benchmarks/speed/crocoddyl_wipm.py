"""The WIPM as a crocoddyl problem: the peer ``wip-bench solvers`` compares our DDP with.

The same discrete problem as ``controllers.simplified.wipm_problem.WIPMProblem`` (the
explicit-Euler step after the paper's eq. ``WIPdyn`` / the 3-D model, the running cost with its
``dt`` factor, the acceleration and ``theta`` penalties, the terminal cost; eq. (1) of
``controllers.optimizer.ddp``), written as a Python action model: a subclass of
``crocoddyl.ActionModelAbstract`` whose ``calc`` and ``calcDiff`` fill crocoddyl's data with NumPy
arrays, node by node, as a user of crocoddyl with a model in Python would. The values come from the
problem's own JAX functions (the dynamics, ``jax.jacfwd`` of it, ``jax.grad`` / ``jax.hessian`` of
the costs: the derivatives the NumPy iLQR peer uses, iLQR's Gauss-Newton terms only), jitted once
per problem, one call per node returning one flat NumPy vector. So every peer solves exactly our
problem; what differs is the solver (crocoddyl's ``SolverDDP``, C++) and the per-node Python model
it calls back.

Solver settings: crocoddyl's ``SolverDDP`` with its own globalisation (regularisation of
``Q_uu`` and ``V_xx``, line search over ``2^0 ... 2^-9``), started at our ``mu_init``. Its
stopping test is ``sum_k ||Q_u||^2 < th_stop`` (the caller's; crocoddyl's default is 1e-9).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import crocoddyl
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from numpy.typing import NDArray

from controllers.simplified.wipm import WIPMParams
from controllers.simplified.wipm_problem import WIPMProblem

__all__ = [
    "CrocoddylResult",
    "CrocoddylWIPM",
    "WIPMActionModel",
    "WIPMTerminalModel",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class _Kernels:
    """The jitted per-node functions of one problem, on flat vectors ``p = [s_ref, params]``:
    ``step(x, u, p) -> [x_next, cost]``, ``step_diff(x, u, p) -> [F_x, F_u, L_x, L_u, L_xx,
    L_xu, L_uu]`` (row-major, flattened), ``terminal(x, p) -> [cost]`` and
    ``terminal_diff(x, p) -> [L_x, L_xx]``."""

    nx: int
    nu: int
    step: Callable[..., Any]
    step_diff: Callable[..., Any]
    terminal: Callable[..., Any]
    terminal_diff: Callable[..., Any]


@functools.lru_cache(maxsize=16)
def _kernels(problem: WIPMProblem, shapes: tuple[tuple[int, ...], ...]) -> _Kernels:
    """Compile-once helpers for ``problem`` (``shapes``: those of the ``WIPMParams`` leaves, for
    the flattening's structure)."""
    params = WIPMParams(*(np.zeros(shape) for shape in shapes))
    n = problem.n_state
    nx = n + problem.n_control if problem.rate_input else n
    nu = problem.n_control
    dynamics = problem.dynamics()
    running, terminal = problem.costs()
    _, unravel = ravel_pytree((jnp.zeros(n), params))

    def step(x: jax.Array, u: jax.Array, p: jax.Array) -> jax.Array:
        s_ref, prm = unravel(p)
        return jnp.concatenate([dynamics(x, u, prm), running(x, u, (s_ref, prm))[None]])

    def step_diff(x: jax.Array, u: jax.Array, p: jax.Array) -> jax.Array:
        s_ref, prm = unravel(p)
        ref = (s_ref, prm)
        fx, fu = jax.jacfwd(dynamics, argnums=(0, 1))(x, u, prm)
        lx, lu = jax.grad(running, argnums=(0, 1))(x, u, ref)
        (lxx, lxu), (_, luu) = jax.hessian(running, argnums=(0, 1))(x, u, ref)
        parts = (fx, fu, lx, lu, lxx, lxu, luu)
        return jnp.concatenate([jnp.ravel(a) for a in parts])

    def terminal_cost(x: jax.Array, p: jax.Array) -> jax.Array:
        s_ref, prm = unravel(p)
        return terminal(x, (s_ref, prm))[None]

    def terminal_diff(x: jax.Array, p: jax.Array) -> jax.Array:
        s_ref, prm = unravel(p)
        ref = (s_ref, prm)
        lx = jax.grad(terminal)(x, ref)
        lxx = jax.hessian(terminal)(x, ref)
        return jnp.concatenate([lx, jnp.ravel(lxx)])

    return _Kernels(
        nx=nx,
        nu=nu,
        step=jax.jit(step),
        step_diff=jax.jit(step_diff),
        terminal=jax.jit(terminal_cost),
        terminal_diff=jax.jit(terminal_diff),
    )


def _flat_params(params: WIPMParams) -> FloatArray:
    return np.asarray(ravel_pytree(params)[0], dtype=np.float64)


class WIPMActionModel(crocoddyl.ActionModelAbstract):
    """One running node: ``x_next = dynamics(x, u)``, ``cost = running(x, u, (s_ref, params))``
    (``controllers.simplified.wipm_problem``), with ``p = [s_ref, params]`` (set by
    :class:`CrocoddylWIPM` before each solve)."""

    def __init__(self, kernels: _Kernels, p: FloatArray) -> None:
        crocoddyl.ActionModelAbstract.__init__(self, crocoddyl.StateVector(kernels.nx), kernels.nu)
        self.kernels = kernels
        self.p = np.array(p, dtype=np.float64)
        nx, nu = kernels.nx, kernels.nu
        sizes = (nx * nx, nx * nu, nx, nu, nx * nx, nx * nu, nu * nu)
        self._splits = np.cumsum(sizes)[:-1]

    def calc(self, data: Any, x: FloatArray, u: FloatArray | None = None) -> None:
        if u is None:  # crocoddyl's convention for a node without control: no motion, no cost
            data.xnext = x
            data.cost = 0.0
            return
        out = np.asarray(self.kernels.step(x, u, self.p))
        data.xnext = out[:-1]
        data.cost = float(out[-1])

    def calcDiff(self, data: Any, x: FloatArray, u: FloatArray | None = None) -> None:  # noqa: N802
        if u is None:
            return
        nx, nu = self.kernels.nx, self.kernels.nu
        fx, fu, lx, lu, lxx, lxu, luu = np.split(
            np.asarray(self.kernels.step_diff(x, u, self.p)), self._splits
        )
        data.Fx = fx.reshape(nx, nx)
        data.Fu = fu.reshape(nx, nu)
        data.Lx = lx
        data.Lu = lu
        data.Lxx = lxx.reshape(nx, nx)
        data.Lxu = lxu.reshape(nx, nu)
        data.Luu = luu.reshape(nu, nu)


class WIPMTerminalModel(crocoddyl.ActionModelAbstract):
    """The terminal node: ``cost = terminal(x, (s_ref, params))``, no control."""

    def __init__(self, kernels: _Kernels, p: FloatArray) -> None:
        crocoddyl.ActionModelAbstract.__init__(self, crocoddyl.StateVector(kernels.nx), 0)
        self.kernels = kernels
        self.p = np.array(p, dtype=np.float64)

    def calc(self, data: Any, x: FloatArray, u: FloatArray | None = None) -> None:
        data.xnext = x
        data.cost = float(np.asarray(self.kernels.terminal(x, self.p))[0])

    def calcDiff(self, data: Any, x: FloatArray, u: FloatArray | None = None) -> None:  # noqa: N802
        nx = self.kernels.nx
        out = np.asarray(self.kernels.terminal_diff(x, self.p))
        data.Lx = out[:nx]
        data.Lxx = out[nx:].reshape(nx, nx)


@dataclass(frozen=True)
class CrocoddylResult:
    """Solver output (NumPy): ``X`` (N+1, nx), ``U`` (N, nu), ``cost``, ``initial_cost`` (of the
    warm start's rollout), ``iterations`` and ``converged`` (crocoddyl's ``solve`` verdict:
    ``sum ||Q_u||^2 < th_stop`` after a feasible step)."""

    X: FloatArray
    U: FloatArray
    cost: float
    initial_cost: float
    iterations: int
    converged: bool


class CrocoddylWIPM:
    """crocoddyl's ``SolverDDP`` on one :class:`WIPMProblem` over a fixed horizon.

    ``solve(x0, U_init, params, s_refs, max_iterations, th_stop)``: ``s_refs`` are the ``N + 1``
    reference states (the ``refs[0]`` leaf of ``controllers.simplified.wipm_problem.refs_for``); the
    problem's nodes keep their models between calls and only their references change, so the
    MPC reuses one problem and one solver (as a crocoddyl MPC would).
    """

    def __init__(
        self, problem: WIPMProblem, params: WIPMParams, horizon: int, mu_init: float
    ) -> None:
        self.kernels = _kernels(problem, tuple(np.shape(leaf) for leaf in params))
        self.horizon = horizon
        self.mu_init = mu_init
        n = problem.n_state
        p = np.concatenate([np.zeros(n), _flat_params(params)])
        self._n = n
        self._params_flat = p[n:].copy()
        self.running = [WIPMActionModel(self.kernels, p) for _ in range(horizon)]
        self.terminal = WIPMTerminalModel(self.kernels, p)
        x0 = np.zeros(self.kernels.nx)
        self.problem = crocoddyl.ShootingProblem(x0, list(self.running), self.terminal)
        self.solver = crocoddyl.SolverDDP(self.problem)

    def _set_references(self, s_refs: FloatArray, params: WIPMParams) -> None:
        flat = _flat_params(params)
        update_params = not np.array_equal(flat, self._params_flat)
        n = self._n
        for model, s_ref in zip(self.running, s_refs[:-1], strict=True):
            model.p[:n] = s_ref
            if update_params:
                model.p[n:] = flat
        self.terminal.p[:n] = s_refs[-1]
        if update_params:
            self.terminal.p[n:] = flat
            self._params_flat = flat

    def solve(
        self,
        x0: FloatArray,
        U_init: FloatArray,
        params: WIPMParams,
        s_refs: FloatArray,
        max_iterations: int,
        th_stop: float,
    ) -> CrocoddylResult:
        """Solve from ``x0`` warm-started from ``U_init`` (its rollout: a feasible start)."""
        U_init = np.asarray(U_init, dtype=np.float64)
        if U_init.shape[0] != self.horizon or len(s_refs) != self.horizon + 1:
            raise ValueError("U_init and s_refs must cover the solver's horizon")
        self._set_references(np.asarray(s_refs, dtype=np.float64), params)
        x0 = np.asarray(x0, dtype=np.float64)
        self.problem.x0 = x0
        xs, us, initial_cost = self._rollout(x0, U_init)
        self.solver.th_stop = th_stop
        converged = bool(self.solver.solve(xs, us, max_iterations, True, self.mu_init))
        return CrocoddylResult(
            X=np.array(self.solver.xs),
            U=np.array(self.solver.us),
            cost=float(self.solver.cost),
            initial_cost=initial_cost,
            iterations=int(self.solver.iter),
            converged=converged,
        )

    def _rollout(
        self, x0: FloatArray, U: FloatArray
    ) -> tuple[list[FloatArray], list[FloatArray], float]:
        """The warm start's states and cost (the feasible start ``solve`` is given; the same
        per-node calls as ``ShootingProblem.rollout``, which does not return the cost)."""
        step = self.kernels.step
        xs = [x0]
        us = list(U)
        cost = 0.0
        for model, u in zip(self.running, us, strict=True):
            out = np.asarray(step(xs[-1], u, model.p))
            xs.append(out[:-1])
            cost += float(out[-1])
        cost += float(np.asarray(self.kernels.terminal(xs[-1], self.terminal.p))[0])
        return xs, us, cost
