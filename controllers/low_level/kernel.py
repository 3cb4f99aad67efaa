"""The low level's arithmetic as one call of fixed shapes per control step.

From the robot's minimal dynamics ``(A, h)`` (paper eq. ``dyn``), the stacked task rows (their
Jacobians ``J`` over ``nu``, reference accelerations ``xdd*``, ``Jdot nu`` and weights ``w``)
and the joint state, one call of :meth:`LowLevelKernel.run` computes, into preallocated buffers:

1. the isolated dynamics, eq. ``iso3`` (``controllers.low_level.isolated_dynamics``, same
   arithmetic): ``calA``, ``Ph`` and ``nu_dot = E qdd + e``;
2. the task QP's rows ``T = w (J E)``, ``b = w (xdd* - Jdot nu - J e)``
   (``controllers.low_level.task_qp``): with ``x`` the first minimal coordinate, ``E``'s rows below
   ``x`` are the identity, so ``J E = J[:, 1:] + J[:, :1] E[0]`` and ``J e = J[:, 0] e[0]`` (no
matrix product); 3. ``H = T^T T + eps I``, ``g = -T^T b``;
4. the constraint rows: actuator torques ``tau_min - M_act Ph <= M_act calA qdd <= tau_max -
   M_act Ph`` and the joint-limit acceleration bounds ``2 (q_lim - q - qd h) / h^2``;
5. the unconstrained minimiser ``H qdd = -g`` (LAPACK ``dposv``) and whether it meets every
   constraint (then it is the convex QP's optimum and no QP solver is needed).

Why NumPy and not a jitted JAX function: for these sizes (Krang: 18 variables, 30 task rows, 34
constraint rows) the whole arithmetic costs less than one call of a jitted function, measured by
``benchmarks/speed/low_level_kernel_bench.py`` (its module docstring has the figures).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg.lapack import dposv

from controllers.low_level.isolated_dynamics import IsolatedDynamics

Array = NDArray[np.float64]


@dataclass(frozen=True)
class KernelLayout:
    """The fixed sizes and constants of one robot's low level.

    Attributes:
        n_min: minimal coordinates (``x`` first); the QP has ``n_min - 1`` variables.
        index_q1: ``q1``'s place inside ``q`` (the minimal coordinates without ``x``).
        wheel_radius: ``R``.
        actuator_map: ``M_act`` (actuators x ``n_min - 1``).
        torque_low, torque_high: actuator limits.
        limit_columns: QP variable of each limited joint; limit_indices: its minimal index.
        limit_min, limit_max: its range. limit_horizon: ``h`` (s).
        regularization: ``eps``.
        rows: the number of stacked task rows.
    """

    n_min: int
    index_q1: int
    wheel_radius: float
    actuator_map: Array
    torque_low: Array
    torque_high: Array
    limit_columns: Array
    limit_indices: Array
    limit_min: Array
    limit_max: Array
    limit_horizon: float
    regularization: float
    rows: int


class LowLevelKernel:
    """Buffers of fixed shapes and the one call that fills them (module docstring)."""

    def __init__(self, layout: KernelLayout) -> None:
        self.layout = layout
        n_min, rows = layout.n_min, layout.rows
        n = n_min - 1
        m = len(layout.actuator_map)
        n_limit = len(layout.limit_columns)
        self.n = n
        self.calA = np.zeros((n, n))
        self.Ph = np.zeros(n)
        self.E = np.eye(n_min, n, k=-1)
        self.e = np.zeros(n_min)
        self.T = np.zeros((rows, n))
        self.b = np.zeros(rows)
        self.H = np.zeros((n, n))
        self.g = np.zeros(n)
        self.C = np.zeros((m + n_limit, n))
        self.C[m + np.arange(n_limit), layout.limit_columns] = 1.0
        self.lower = np.zeros(m + n_limit)
        self.upper = np.zeros(m + n_limit)
        self.x = np.zeros(n)
        self._m = m
        self._outer = np.zeros((n, n))
        self._A_star = np.zeros((n, n))
        self._diagonal = np.arange(n)
        self._limit_square = layout.limit_horizon**2

    def run(
        self,
        A: Array,
        h: Array,
        J: Array,
        target: Array,
        jdot_nu: Array,
        w: Array,
        q: Array,
        nu: Array,
        iso: IsolatedDynamics | None = None,
    ) -> bool:
        """Fill every buffer for this state; True when the unconstrained minimiser ``x`` meets
        every constraint (it is then the QP's optimum). With ``iso`` given, its ``calA``,
        ``Ph``, ``E``, ``e`` are used instead of step 1."""
        if iso is None:
            self._isolated_dynamics(A, h)
        else:
            self.calA[:] = iso.calA
            self.Ph[:] = iso.Ph
            self.E[:] = iso.E
            self.e[:] = iso.e
        return self._rows_and_solve(J, target, jdot_nu, w, q, nu)

    def _isolated_dynamics(self, A: Array, h: Array) -> None:
        """Step 1: eq. iso3 (``controllers.low_level.isolated_dynamics``, operation for
        operation)."""
        lay = self.layout
        k, r = lay.index_q1, lay.wheel_radius
        a_xx = float(A[0, 0])
        a_xq = A[1:, 0]
        h_x, h_q = float(h[0]), h[1:]
        outer, A_star, calA = self._outer, self._A_star, self.calA
        np.multiply(a_xq[:, None], a_xq, out=outer)
        outer /= a_xx
        np.subtract(A[1:, 1:], outer, out=A_star)
        beta = 1.0 / (1.0 + float(a_xq[k]) / (r * a_xx))
        scale = beta / (r * a_xx)
        np.multiply(a_xq[:, None], A_star[k], out=outer)
        outer *= scale
        np.subtract(A_star, outer, out=calA)
        h_star = h_q - a_xq * h_x / a_xx
        Ph = self.Ph
        np.subtract(h_star, scale * a_xq * float(h_star[k]), out=Ph)
        E0 = self.E[0]
        np.divide(-calA[k] / r - a_xq, a_xx, out=E0)
        self.e[0] = (-float(Ph[k]) / r - h_x) / a_xx

    def _rows_and_solve(
        self, J: Array, target: Array, jdot_nu: Array, w: Array, q: Array, nu: Array
    ) -> bool:
        """Steps 2 to 5."""
        lay = self.layout
        E0, e0, calA, Ph = self.E[0], float(self.e[0]), self.calA, self.Ph
        # 2. task rows
        T, b = self.T, self.b
        column = J[:, 0]
        np.multiply(column[:, None], E0, out=T)
        T += J[:, 1:]
        T *= w[:, None]
        np.subtract(target, jdot_nu, out=b)
        b -= column * e0
        b *= w
        # 3. the cost
        H, g = self.H, self.g
        np.matmul(T.T, T, out=H)
        H[self._diagonal, self._diagonal] += lay.regularization
        np.matmul(T.T, b, out=g)
        np.negative(g, out=g)
        # 4. constraints
        m, C, lower, upper = self._m, self.C, self.lower, self.upper
        np.matmul(lay.actuator_map, calA, out=C[:m])
        offset = lay.actuator_map @ Ph
        np.subtract(lay.torque_low, offset, out=lower[:m])
        np.subtract(lay.torque_high, offset, out=upper[:m])
        index = lay.limit_indices
        drift = q[index] + nu[index] * lay.limit_horizon
        np.subtract(lay.limit_min, drift, out=lower[m:])
        np.subtract(lay.limit_max, drift, out=upper[m:])
        for bound in (lower[m:], upper[m:]):
            bound *= 2.0
            bound /= self._limit_square
        # 5. the unconstrained minimiser and its feasibility
        _, x, info = dposv(H, g, overwrite_b=False)
        if info != 0:
            return False
        np.negative(x, out=self.x)
        Cx = C @ self.x
        return bool(np.isfinite(Cx).all() and (Cx >= lower).all() and (Cx <= upper).all())
