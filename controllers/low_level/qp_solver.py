"""The task QP's solver side (``controllers.low_level.task_qp``): its settings, the dense ProxQP
object it warm-starts step to step, and the unconstrained minimiser it tries first."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import proxsuite
from numpy.typing import NDArray
from scipy.linalg.lapack import dposv

Array = NDArray[np.float64]


@dataclass(frozen=True)
class QPSettings:
    """Attributes:
    regularization: ``eps`` on ``||qdd||^2`` (keeps the Hessian positive definite).
    eps_abs: ProxQP's absolute tolerance. Its default (1e-5 on the KKT residual) can stop
        with constraint errors of order 1e-3 N m here; 1e-9 gives answers that are right.
    limit_horizon: ``h`` of the joint-limit acceleration bounds (s).
    max_iterations: ProxQP's iteration cap (its default, 10000, lets an infeasible QP run for
        a minute before it gives up; a feasible one here takes under 20).
    unconstrained_first: try the unconstrained minimiser before ProxQP
        (``controllers.low_level.task_qp``).
    compiled_tasks: the compiled path where it applies (``controllers.low_level.task_qp``);
        False: always the readable one (the reference it is tested against).
    """

    regularization: float = 1e-6
    eps_abs: float = 1e-9
    limit_horizon: float = 0.05
    max_iterations: int = 1000
    unconstrained_first: bool = True
    compiled_tasks: bool = True


def feasible_unconstrained_minimiser(
    H: Array, g: Array, C: Array, lower: Array, upper: Array
) -> Array | None:
    """``x = -H^-1 g`` (one LAPACK Cholesky solve; ``H`` is symmetric positive definite, being
    regularised) when it meets every constraint: then it is the convex QP's exact optimum.
    None otherwise (the QP needs a solver)."""
    _, x, info = dposv(H, -g)
    if info != 0 or not np.isfinite(x).all():
        return None
    Cx = C @ x
    return x if (Cx >= lower).all() and (Cx <= upper).all() else None


def start_proxqp(
    H: Array, g: Array, C: Array, lower: Array, upper: Array, settings: QPSettings
) -> proxsuite.proxqp.dense.QP:
    """A dense ProxQP object for this QP, configured as ``settings`` says, solved once, and
    set to warm start every later ``update`` + ``solve`` from the previous result."""
    qp = proxsuite.proxqp.dense.QP(len(g), 0, len(C))
    qp.settings.eps_abs = settings.eps_abs
    qp.settings.eps_rel = 0.0
    # no preconditioner: its scaling, computed once from the first H and kept by update(),
    # stalls badly conditioned task weightings (a weight-100 theta task alone never converged
    # with it)
    qp.settings.max_iter = settings.max_iterations
    qp.init(H, g, None, None, C, lower, upper, compute_preconditioner=False)
    qp.solve()
    # warm start only once a previous result exists (ProxQP 0.8 crashes otherwise)
    qp.settings.initial_guess = proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
    return qp
