"""The task-QP solvers ``wip-bench solvers`` compares, behind one interface.

Every solver takes the recorded sequence (:mod:`benchmarks.speed.qp_recording`) in order, one QP
per control step, ``min 0.5 x'Hx + g'x  s.t.  lower <= C x <= upper``:

* ``proxqp`` (ours): ``controllers.low_level.task_qp``'s path exactly: one dense ProxQP object, no
  preconditioner, ``eps_abs`` and the iteration cap of ``QPSettings``, ``eps_rel = 0``, warm
  started from the previous result after the first solve; each step ``update`` + ``solve``;
  the ratios are against this path;
* ``proxqp_shortcut`` (ours, what the controller runs): the unconstrained minimiser by one
  Cholesky solve when it is feasible (then exact), ProxQP as above otherwise;
* ``osqp``: OSQP with tight tolerances (:data:`OSQP_EPS`), solution polishing, warm started
  (its default) step to step; the full dense pattern kept so ``update(Px, Ax)`` applies;
* ``daqp``: DAQP (dual active set), from scratch each step (its Python ``solve``);
* ``quadprog``: Goldfarb-Idnani dual active set, from scratch each step (no warm start API);
* ``slsqp``: SciPy's SLSQP (the algorithm of the authors' code), started from the previous
  solution, ``ftol`` :data:`SLSQP_FTOL`, analytic gradients and constraint Jacobians. At that
  tolerance SLSQP often ends with exit mode 8 ("positive directional derivative for
  linesearch": no further decrease representable), at its precision limit rather than lost;
  such an ending is counted in ``stalled`` and its ``x`` checked like any other (looser
  ``ftol`` values end "successfully" with errors above 1e-6 on the recorded QPs).

The reference solution of each QP is quadprog's (an exact active-set method), accepted only if
its KKT conditions hold (:func:`reference_solution`). A solver agrees when
``||x - x_ref||_inf <= 1e-6 max(1, ||x_ref||_inf)`` on every QP.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import daqp
import numpy as np
import osqp
import proxsuite
import quadprog
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.optimize import minimize

from benchmarks.speed.qp_recording import RecordedQP
from controllers.low_level.qp_solver import (
    QPSettings,
    feasible_unconstrained_minimiser,
    start_proxqp,
)

FloatArray = NDArray[np.float64]
SOLUTION_TOLERANCE = 1e-6
KKT_TOLERANCE = 1e-8
OSQP_EPS = 1e-10
SLSQP_FTOL = 1e-14
SLSQP_STALLED = 8  # "Positive directional derivative for linesearch"
_PROXQP_SOLVED = proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED


class QPSolver(ABC):
    """One solver over a sequence: :meth:`start` before the first QP (drops any warm start),
    :meth:`solve` per QP, returning ``x`` or raising ``RuntimeError`` with the solver's status."""

    name: str
    settings: dict[str, Any]
    stalled: int = 0  # solves that ended at the solver's precision limit (SLSQP's mode 8)

    @abstractmethod
    def start(self) -> None: ...

    @abstractmethod
    def solve(self, qp: RecordedQP) -> FloatArray: ...


class ProxQPOurs(QPSolver):
    """``controllers.low_level.task_qp.TaskQP.solve``'s ProxQP configuration (module docstring)."""

    name = "proxqp"

    def __init__(self, settings: QPSettings | None = None) -> None:
        self.qp_settings = settings or QPSettings()
        self.settings = {
            "backend": "dense",
            "eps_abs": self.qp_settings.eps_abs,
            "eps_rel": 0.0,
            "max_iter": self.qp_settings.max_iterations,
            "preconditioner": False,
            "warm_start": "previous result",
        }
        self._qp: Any = None

    def start(self) -> None:
        self._qp = None

    def solve(self, qp: RecordedQP) -> FloatArray:
        if self._qp is None:
            self._qp = start_proxqp(qp.H, qp.g, qp.C, qp.lower, qp.upper, self.qp_settings)
        else:
            self._qp.update(H=qp.H, g=qp.g, C=qp.C, l=qp.lower, u=qp.upper)
            self._qp.solve()
        info = self._qp.results.info
        if info.status != _PROXQP_SOLVED:
            self._qp = None  # as the controller: the next QP starts cold
            raise RuntimeError(f"ProxQP status {info.status}")
        return np.array(self._qp.results.x)


class ControllerPath(ProxQPOurs):
    """What the controller runs each step (``QPSettings.unconstrained_first``): the
    unconstrained minimiser ``H x = -g`` by one LAPACK Cholesky solve, kept when it satisfies
    every constraint (then it is the convex QP's exact optimum), otherwise ProxQP as
    :class:`ProxQPOurs`, warm started."""

    name = "proxqp_shortcut"

    def __init__(self, settings: QPSettings | None = None) -> None:
        super().__init__(settings)
        self.settings = {**self.settings, "unconstrained_first": True}

    def solve(self, qp: RecordedQP) -> FloatArray:
        if self._qp is not None:
            x = feasible_unconstrained_minimiser(qp.H, qp.g, qp.C, qp.lower, qp.upper)
            if x is not None:
                return x
        return super().solve(qp)


class OSQPSolver(QPSolver):
    """OSQP, dense pattern, tight tolerances, polished, warm started (module docstring)."""

    name = "osqp"

    def __init__(self) -> None:
        self.settings = {
            "eps_abs": OSQP_EPS,
            "eps_rel": OSQP_EPS,
            "polishing": True,
            "warm_starting": True,
            "max_iter": 100000,
        }
        self._prob: Any = None

    def start(self) -> None:
        self._prob = None

    def solve(self, qp: RecordedQP) -> FloatArray:
        if self._prob is None:
            n, m = qp.n, qp.m
            self._rows, self._cols = np.triu_indices(n)
            order = np.lexsort((self._rows, self._cols))  # CSC: column by column, rows sorted
            self._rows, self._cols = self._rows[order], self._cols[order]
            counts = np.bincount(self._cols, minlength=n)
            indptr = np.concatenate([[0], np.cumsum(counts)])
            P = sp.csc_matrix((qp.H[self._rows, self._cols], self._rows, indptr), shape=(n, n))
            A = sp.csc_matrix(
                (qp.C.ravel(order="F"), np.tile(np.arange(m), n), np.arange(0, m * n + 1, m)),
                shape=(m, n),
            )
            self._prob = osqp.OSQP()
            self._prob.setup(P, qp.g, A, qp.lower, qp.upper, verbose=False, **self.settings)
        else:
            self._prob.update(
                q=qp.g,
                l=qp.lower,
                u=qp.upper,
                Px=qp.H[self._rows, self._cols],
                Ax=qp.C.ravel(order="F"),
            )
        result = self._prob.solve(raise_error=False)
        status = result.info.status
        if status != "solved":
            raise RuntimeError(f"OSQP status {status!r}")
        return np.array(result.x)


class DAQPSolver(QPSolver):
    """DAQP from scratch each step (module docstring)."""

    name = "daqp"

    def __init__(self) -> None:
        self.settings = {"warm_start": False}

    def start(self) -> None:
        pass

    def solve(self, qp: RecordedQP) -> FloatArray:
        x, _, exitflag, _ = daqp.solve(qp.H, qp.g, qp.C, qp.upper, qp.lower)
        if exitflag != 1:
            raise RuntimeError(f"DAQP exit flag {exitflag}")
        return np.asarray(x, dtype=np.float64)


def _quadprog(qp: RecordedQP) -> tuple[FloatArray, FloatArray]:
    """quadprog's ``x`` and multipliers of ``[C; -C] x >= [lower; -upper]``."""
    C = np.vstack([qp.C, -qp.C])
    b = np.concatenate([qp.lower, -qp.upper])
    x, _, _, _, multipliers, _ = quadprog.solve_qp(qp.H, -qp.g, C.T, b, 0)
    return np.asarray(x), np.asarray(multipliers)


class QuadprogSolver(QPSolver):
    """quadprog from scratch each step (module docstring)."""

    name = "quadprog"

    def __init__(self) -> None:
        self.settings = {"warm_start": False}

    def start(self) -> None:
        pass

    def solve(self, qp: RecordedQP) -> FloatArray:
        try:
            return _quadprog(qp)[0]
        except ValueError as error:  # quadprog raises ValueError for an infeasible QP
            raise RuntimeError(f"quadprog: {error}") from error


class SLSQPSolver(QPSolver):
    """SciPy's SLSQP, started from the previous solution (module docstring)."""

    name = "slsqp"

    def __init__(self) -> None:
        self.settings = {"ftol": SLSQP_FTOL, "maxiter": 1000, "warm_start": "previous solution"}
        self._x: FloatArray | None = None

    def start(self) -> None:
        self._x = None
        self.stalled = 0

    def solve(self, qp: RecordedQP) -> FloatArray:
        H, g, C = qp.H, qp.g, qp.C
        x0 = self._x if self._x is not None and self._x.shape == g.shape else np.zeros_like(g)
        constraints = (
            {"type": "ineq", "fun": lambda x: C @ x - qp.lower, "jac": lambda x: C},
            {"type": "ineq", "fun": lambda x: qp.upper - C @ x, "jac": lambda x: -C},
        )
        result = minimize(
            lambda x: 0.5 * x @ H @ x + g @ x,
            x0,
            jac=lambda x: H @ x + g,
            method="SLSQP",
            constraints=constraints,
            options={"ftol": SLSQP_FTOL, "maxiter": 1000},
        )
        if result.status == SLSQP_STALLED:
            self.stalled += 1
        elif not result.success:
            raise RuntimeError(f"SLSQP exit mode {result.status}: {result.message}")
        self._x = np.asarray(result.x)
        return self._x


def all_solvers() -> list[QPSolver]:
    """Ours first, then the peers."""
    return [
        ProxQPOurs(),
        ControllerPath(),
        OSQPSolver(),
        DAQPSolver(),
        QuadprogSolver(),
        SLSQPSolver(),
    ]


def reference_solution(qp: RecordedQP) -> tuple[FloatArray, dict[str, float]]:
    """quadprog's solution, checked against the KKT conditions of the QP: primal feasibility,
    non-negative multipliers, stationarity ``H x + g - [C; -C]' lambda = 0`` and complementary
    slackness, each scaled by the problem's magnitude and required below
    :data:`KKT_TOLERANCE` (``RuntimeError`` otherwise). Returns ``x`` and the residuals."""
    x, lam = _quadprog(qp)
    C2 = np.vstack([qp.C, -qp.C])
    b2 = np.concatenate([qp.lower, -qp.upper])
    slack = C2 @ x - b2
    scale = 1.0 + max(np.abs(qp.g).max(), np.abs(b2).max(), np.abs(qp.H).max())
    residuals = {
        "primal": float(max(-slack.min(), 0.0)) / scale,
        "dual_sign": float(max(-lam.min(), 0.0)) / scale,
        "stationarity": float(np.abs(qp.H @ x + qp.g - C2.T @ lam).max()) / scale,
        "complementarity": float(np.abs(lam * slack).max()) / scale**2,
    }
    if max(residuals.values()) > KKT_TOLERANCE:
        raise RuntimeError(f"the reference solution fails its KKT check: {residuals}")
    return x, residuals


def solution_error(x: FloatArray, x_ref: FloatArray) -> float:
    """``||x - x_ref||_inf / max(1, ||x_ref||_inf)``."""
    return float(np.abs(x - x_ref).max() / max(1.0, float(np.abs(x_ref).max())))
