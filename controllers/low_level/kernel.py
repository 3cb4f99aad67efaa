"""The low level's arithmetic as one call of fixed shapes per control step.

From the robot's minimal dynamics ``(A, h)`` (paper eq. ``dyn``), the stacked task rows (their
Jacobians ``J`` over ``nu``, reference accelerations ``xdd*``, ``Jdot nu`` and weights ``w``),
the extra constraint rows (``lower <= G nu_dot + bias <= upper``) and the joint state, one call
of :func:`kernel_step` computes, into preallocated buffers:

1. the isolated dynamics, eq. ``iso3`` (``controllers.low_level.isolated_dynamics``'s
   formulas, with products by ``1 / a_xx`` for its divisions): ``calA``, ``Ph`` and
   ``nu_dot = E qdd + e``;
2. the task QP's rows ``T = w (J E)``, ``b = w (xdd* - Jdot nu - J e)``
   (``controllers.low_level.task_qp``): with ``x`` the first minimal coordinate, ``E``'s rows
   below ``x`` are the identity, so ``J E = J[:, 1:] + J[:, :1] E[0]`` and ``J e = J[:, 0]
   e[0]`` (no matrix product);
3. ``H = T^T T + eps I``, ``g = -T^T b``;
4. the constraint rows: actuator torques ``tau_min - M_act Ph <= M_act calA qdd <= tau_max -
   M_act Ph``, the joint-limit acceleration bounds ``2 (q_lim - q - qd h) / h^2``, then the
   extra rows ``G E qdd`` within ``[lower - bias - G e, upper - bias - G e]``;
5. the unconstrained minimiser ``H qdd = -g`` (a Cholesky factorisation and two triangular
   solves) and whether it is finite and meets every constraint row (then it is the convex QP's
   optimum and no QP solver is needed).

Compiled by numba, one call for the five steps, its arrays declared once (:data:`KERNEL`). For
these sizes (KrangTray-v0: 18 variables, 30 task rows, 34 constraint rows) the arithmetic costs
less than one call of a jitted JAX function, and NumPy spends more in its per-call overhead
than in arithmetic (docs/performance.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from controllers.low_level.isolated_dynamics import IsolatedDynamics
from wip_gym.array_table import (
    FLOAT_MATRIX,
    FLOAT_VECTOR,
    INT_VECTOR,
    TableSpec,
    float_matrix,
    float_vector,
    int_vector,
)
from wip_gym.small_linalg import (
    gram_into,
    matmul_into,
    matvec_into,
    matvec_transposed_into,
    row_dot,
)

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
        constraint_rows: the number of extra constraint rows (``controllers.low_level.tasks``'
            constraints), after the actuators' and the joint limits'.
    """

    n_min: int
    index_q1: int
    wheel_radius: float
    actuator_map: Array
    torque_low: Array
    torque_high: Array
    limit_columns: Array
    limit_indices: NDArray[np.int64]
    limit_min: Array
    limit_max: Array
    limit_horizon: float
    regularization: float
    rows: int
    constraint_rows: int = 0


def _check_layout(layout: KernelLayout, m: int, n_limit: int) -> None:
    """``ValueError`` for a layout whose arrays the compiled step would read past: it reads
    them without bounds checks (a torque limit too few gave a bound from memory past its
    array). The torque limits are read at every call, so ``TaskQP`` makes a new kernel when
    they are assigned; this runs then too."""
    n_min, n = layout.n_min, layout.n_min - 1
    actuator_map = np.asarray(layout.actuator_map)
    if actuator_map.ndim != 2 or actuator_map.shape[1] != n:
        raise ValueError(f"the actuator map must be (actuators, {n}), got {actuator_map.shape}")
    for name in ("torque_low", "torque_high"):
        shape = np.shape(getattr(layout, name))
        if shape != (m,):
            raise ValueError(f"{name} must hold one limit per actuator, ({m},), got {shape}")
    if not 0 <= layout.index_q1 < n:
        raise ValueError(
            f"index_q1 must be a QP variable's index (0 to {n - 1}), got {layout.index_q1}"
        )
    columns = np.asarray(layout.limit_columns)
    indices = np.asarray(layout.limit_indices)
    if columns.shape != (n_limit,) or indices.shape != (n_limit,):
        raise ValueError("limit_columns and limit_indices must be 1-D and as long as each other")
    for values, name, size in ((columns, "limit_columns", n), (indices, "limit_indices", n_min)):
        if n_limit and not ((values >= 0) & (values < size)).all():
            raise ValueError(f"{name} must be indices in 0 to {size - 1}, got {values.tolist()}")
    for name in ("limit_min", "limit_max"):
        if np.shape(getattr(layout, name)) != (n_limit,):
            raise ValueError(f"{name} must hold one value per joint limit, ({n_limit},)")
    if layout.rows < 0 or layout.constraint_rows < 0:
        raise ValueError(f"rows must be >= 0, got {layout.rows} and {layout.constraint_rows}")


KERNEL = TableSpec(
    "kernel",
    (
        ("A", FLOAT_MATRIX),  # inputs: eq. dyn (read when eq. iso3 is computed here)
        ("h", FLOAT_VECTOR),
        ("q", FLOAT_VECTOR),
        ("nu", FLOAT_VECTOR),
        ("J", FLOAT_MATRIX),  # the stacked task rows
        ("target", FLOAT_VECTOR),
        ("jdot_nu", FLOAT_VECTOR),
        ("w", FLOAT_VECTOR),
        ("G", FLOAT_MATRIX),  # the extra constraint rows
        ("constraint_lower", FLOAT_VECTOR),
        ("constraint_bias", FLOAT_VECTOR),
        ("constraint_upper", FLOAT_VECTOR),
        ("calA", FLOAT_MATRIX),  # eq. iso3 (computed here, or given)
        ("Ph", FLOAT_VECTOR),
        ("E", FLOAT_MATRIX),
        ("e", FLOAT_VECTOR),
        ("actuator_map", FLOAT_MATRIX),  # constants
        ("torque_low", FLOAT_VECTOR),
        ("torque_high", FLOAT_VECTOR),
        ("limits", FLOAT_MATRIX),
        ("limit_indices", INT_VECTOR),
        ("constants", FLOAT_VECTOR),  # limit horizon, regularization, wheel radius
        ("index_q1", INT_VECTOR),
        ("T", FLOAT_MATRIX),  # outputs
        ("b", FLOAT_VECTOR),
        ("H", FLOAT_MATRIX),
        ("g", FLOAT_VECTOR),
        ("C", FLOAT_MATRIX),
        ("lower", FLOAT_VECTOR),
        ("upper", FLOAT_VECTOR),
        ("x", FLOAT_VECTOR),
        ("generalized", FLOAT_VECTOR),  # what a feasible x implies (solution_terms_into)
        ("actuators", FLOAT_VECTOR),
        ("nu_dot", FLOAT_VECTOR),
    ),
)
"""The arrays of :func:`kernel_step`: its table's first rows, in the one-call step's table too
(``controllers.low_level.compiled_step``)."""
_K = KERNEL.index


class LowLevelKernel:
    """Buffers of fixed shapes and the one call that fills them (module docstring). The rows'
    inputs (``J``, ``target``, ``jdot_nu``, ``w`` of the tasks; ``G``, ``constraint_lower``,
    ``constraint_bias``, ``constraint_upper`` of the extra constraints) are buffers of the
    kernel that the caller fills."""

    def __init__(self, layout: KernelLayout) -> None:
        self.layout = layout
        n_min, rows, extra = layout.n_min, layout.rows, layout.constraint_rows
        n = n_min - 1
        m = len(layout.actuator_map)
        n_limit = len(layout.limit_columns)
        _check_layout(layout, m, n_limit)
        unreached = np.flatnonzero(~(np.asarray(layout.actuator_map) != 0.0).any(axis=0))
        if len(unreached):
            # the constraint rows M_act calA skip zero entries (small_linalg.matmul_into): a
            # variable no actuator reaches would keep a nonfinite calA row out of them
            raise ValueError(
                f"the actuator map's columns {unreached.tolist()} are all zeros: every QP "
                "variable must reach an actuator"
            )
        self.n = n
        self.J = np.zeros((rows, n_min))
        self.target = np.zeros(rows)
        self.jdot_nu = np.zeros(rows)
        self.w = np.zeros(rows)
        self.G = np.zeros((extra, n_min))
        self.constraint_lower = np.zeros(extra)
        self.constraint_bias = np.zeros(extra)
        self.constraint_upper = np.zeros(extra)
        self.calA = np.zeros((n, n))
        self.Ph = np.zeros(n)
        self.E = np.eye(n_min, n, k=-1)
        self.e = np.zeros(n_min)
        self.T = np.zeros((rows, n))
        self.b = np.zeros(rows)
        self.H = np.zeros((n, n))
        self.g = np.zeros(n)
        self.C = np.zeros((m + n_limit + extra, n))
        self.C[m + np.arange(n_limit), layout.limit_columns] = 1.0
        self.lower = np.zeros(m + n_limit + extra)
        self.upper = np.zeros(m + n_limit + extra)
        self.x = np.zeros(n)
        # what x implies (solution_terms_into), filled by the one-call step when x is feasible
        self.generalized = np.zeros(n)
        self.actuators = np.zeros(m)
        self.nu_dot = np.zeros(n_min)
        # the readable path's copies of the state and eq. dyn (the one-call step reads the
        # robot's own buffers instead)
        self._A, self._h = np.zeros((n_min, n_min)), np.zeros(n_min)
        self._q, self._nu = np.zeros(n_min), np.zeros(n_min)
        # the joints' ranges, fixed when the kernel is made (the model's jnt_range); the torque
        # limits are read at every call
        self._limits = np.array([layout.limit_min, layout.limit_max], dtype=float).reshape(
            2, n_limit
        )
        self._limit_indices = np.asarray(layout.limit_indices, dtype=np.int64)
        self._constants = np.array(
            [layout.limit_horizon, layout.regularization, layout.wheel_radius]
        )
        self._index_q1 = np.array([layout.index_q1], dtype=np.int64)
        self._table = KERNEL.table(self.buffers())

    def __getstate__(self) -> dict[str, object]:
        state = self.__dict__.copy()
        del state["_table"]  # addresses: made again from the copied buffers
        return state

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)
        self._table = KERNEL.table(self.buffers())

    def buffers(self) -> dict[str, np.ndarray]:
        """The arrays of :data:`KERNEL` by name (``A``, ``h``, ``q``, ``nu``: the readable
        path's copies, which the one-call step replaces by the robot's buffers)."""
        lay = self.layout
        return {
            "A": self._A,
            "h": self._h,
            "q": self._q,
            "nu": self._nu,
            "J": self.J,
            "target": self.target,
            "jdot_nu": self.jdot_nu,
            "w": self.w,
            "G": self.G,
            "constraint_lower": self.constraint_lower,
            "constraint_bias": self.constraint_bias,
            "constraint_upper": self.constraint_upper,
            "calA": self.calA,
            "Ph": self.Ph,
            "E": self.E,
            "e": self.e,
            "actuator_map": np.ascontiguousarray(lay.actuator_map, dtype=float),
            "torque_low": lay.torque_low,  # read every call: limits may be changed in place
            "torque_high": lay.torque_high,
            "limits": self._limits,
            "limit_indices": self._limit_indices,
            "constants": self._constants,
            "index_q1": self._index_q1,
            "T": self.T,
            "b": self.b,
            "H": self.H,
            "g": self.g,
            "C": self.C,
            "lower": self.lower,
            "upper": self.upper,
            "x": self.x,
            "generalized": self.generalized,
            "actuators": self.actuators,
            "nu_dot": self.nu_dot,
        }

    def run(
        self,
        A: Array | None,
        h: Array | None,
        J: Array,
        target: Array,
        jdot_nu: Array,
        w: Array,
        q: Array,
        nu: Array,
        iso: IsolatedDynamics | None = None,
        constraints: tuple[Array, Array, Array, Array] | None = None,
    ) -> bool:
        """Fill every buffer for this state; True when the unconstrained minimiser ``x`` meets
        every constraint (it is then the QP's optimum). The rows are copied into the kernel's
        buffers (the extra constraints' as ``(G, lower, bias, upper)``, none when the layout
        has none). With ``iso`` given, its ``calA``, ``Ph``, ``E``, ``e`` are used instead of
        step 1 (``A``, ``h`` not read). ``ValueError`` for arrays of other shapes than the
        layout's (the compiled step reads them unchecked)."""
        n_min = self.layout.n_min
        inputs = [
            ("J", J, self.J),
            ("target", target, self.target),
            ("jdot_nu", jdot_nu, self.jdot_nu),
            ("w", w, self.w),
            ("q", q, self._q),
            ("nu", nu, self._nu),
        ]
        if constraints is not None:
            buffers = (self.G, self.constraint_lower, self.constraint_bias, self.constraint_upper)
            names = ("G", "constraint lower", "constraint bias", "constraint upper")
            inputs += zip(names, constraints, buffers, strict=True)
        elif self.layout.constraint_rows:
            raise ValueError(f"{self.layout.constraint_rows} constraint rows expected, none given")
        if iso is None:
            if np.shape(A) != (n_min, n_min) or np.shape(h) != (n_min,):
                raise ValueError(
                    f"A and h must be ({n_min}, {n_min}) and ({n_min},), got "
                    f"{np.shape(A)} and {np.shape(h)}"
                )
            inputs += [("A", A, self._A), ("h", h, self._h)]
        for name, array, buffer in inputs:
            if np.shape(array) != buffer.shape:
                raise ValueError(
                    f"{name} must be {buffer.shape} for this kernel, got {np.shape(array)}"
                )
            buffer[...] = array
        if iso is not None:
            self.calA[:] = iso.calA
            self.Ph[:] = iso.Ph
            self.E[:] = iso.E
            self.e[:] = iso.e
        return bool(kernel_step(self._table.rows, iso is None))


@njit(cache=True, nogil=True)
def kernel_step(table: np.ndarray, with_iso: bool) -> bool:
    """Steps 1 (:func:`isolated_dynamics_into`; skipped when ``with_iso`` is False: ``calA``,
    ``Ph``, ``E``, ``e`` given) to 5 in one call, on the arrays of ``table`` (:data:`KERNEL`,
    or a table whose first rows are its). ``limits``: rows joint-limit min and max;
    ``constants``: ``(limit_horizon, regularization, wheel_radius)``. The extra constraint rows
    ``lower <= G nu_dot + bias <= upper`` follow the joint limits in ``C``, ``lower``,
    ``upper``, as ``G E qdd`` within ``[lower - bias - G e, upper - bias - G e]``."""
    calA, Ph = float_matrix(table[_K.calA]), float_vector(table[_K.Ph])
    E, e = float_matrix(table[_K.E]), float_vector(table[_K.e])
    constants = float_vector(table[_K.constants])
    if with_iso:
        isolated_dynamics_into(
            float_matrix(table[_K.A]),
            float_vector(table[_K.h]),
            int_vector(table[_K.index_q1])[0],
            constants[2],
            calA,
            Ph,
            E,
            e,
        )
    horizon, regularization = constants[0], constants[1]
    J, target = float_matrix(table[_K.J]), float_vector(table[_K.target])
    jdot_nu, w = float_vector(table[_K.jdot_nu]), float_vector(table[_K.w])
    T, b = float_matrix(table[_K.T]), float_vector(table[_K.b])
    H, g = float_matrix(table[_K.H]), float_vector(table[_K.g])
    C, x = float_matrix(table[_K.C]), float_vector(table[_K.x])
    lower, upper = float_vector(table[_K.lower]), float_vector(table[_K.upper])
    actuator_map = float_matrix(table[_K.actuator_map])
    E0, e0 = E[0], e[0]
    rows, n = T.shape
    # 2. task rows
    for i in range(rows):
        column = J[i, 0]
        for j in range(n):
            T[i, j] = (column * E0[j] + J[i, 1 + j]) * w[i]
        b[i] = (target[i] - jdot_nu[i] - column * e0) * w[i]
    # 3. the cost
    gram_into(T, H)
    for i in range(n):
        H[i, i] += regularization
    matvec_transposed_into(T, b, g)
    for j in range(n):
        g[j] = -g[j]
    # 4. constraints: the actuators, the joint limits, the extra rows
    m = actuator_map.shape[0]
    matmul_into(actuator_map, calA, C[:m])
    torque_low, torque_high = (
        float_vector(table[_K.torque_low]),
        float_vector(table[_K.torque_high]),
    )
    for i in range(m):
        offset = row_dot(actuator_map, i, Ph)
        lower[i] = torque_low[i] - offset
        upper[i] = torque_high[i] - offset
    q, nu = float_vector(table[_K.q]), float_vector(table[_K.nu])
    limits, limit_indices = float_matrix(table[_K.limits]), int_vector(table[_K.limit_indices])
    square = horizon * horizon
    for i in range(len(limit_indices)):
        index = limit_indices[i]
        drift = q[index] + nu[index] * horizon
        lower[m + i] = (limits[0, i] - drift) * 2.0 / square
        upper[m + i] = (limits[1, i] - drift) * 2.0 / square
    G = float_matrix(table[_K.G])
    bias = float_vector(table[_K.constraint_bias])
    low, high = float_vector(table[_K.constraint_lower]), float_vector(table[_K.constraint_upper])
    first = m + len(limit_indices)
    for i in range(G.shape[0]):
        column = G[i, 0]
        for j in range(n):
            C[first + i, j] = column * E0[j] + G[i, 1 + j]
        offset = bias[i] + column * e0
        lower[first + i] = low[i] - offset
        upper[first + i] = high[i] - offset
    # 5. the unconstrained minimiser and its feasibility
    if not _cholesky_solve(H, -g, x):
        return False
    # a nonfinite x would make every constraint row nonfinite too (their products do not skip
    # zeros); tested here as well, cheaply, so that no later change of those rows can let it
    # through
    for i in range(n):  # noqa: SIM110 (a generator in all() does not compile)
        if not np.isfinite(x[i]):
            return False
    for i in range(C.shape[0]):
        Cx = row_dot(C, i, x)
        if not (np.isfinite(Cx) and lower[i] <= Cx <= upper[i]):
            return False
    return True


@njit(cache=True)
def isolated_dynamics_into(
    A: Array,
    h: Array,
    k: int,
    r: float,
    calA: Array,
    Ph: Array,
    E: Array,
    e: Array,
) -> None:
    """Step 1: eq. iso3 (``controllers.low_level.isolated_dynamics``: the same formulas, each
    division by ``a_xx`` a product with its reciprocal, and ``a_xq`` copied to a contiguous
    array first; equal to rounding) into ``calA``, ``Ph`` and the first rows of ``E``, ``e``."""
    n = A.shape[0] - 1
    a_xx = A[0, 0]
    inverse = 1.0 / a_xx
    h_x = h[0]
    work = np.empty(2 * n)  # a_xq, then calA's row k before its update
    a_xq, row_k = work[:n], work[n:]
    for i in range(n):
        a_xq[i] = A[1 + i, 0]
    for i in range(n):
        a_i = a_xq[i] * inverse
        for j in range(n):
            calA[i, j] = A[1 + i, 1 + j] - a_i * a_xq[j]
    beta = 1.0 / (1.0 + a_xq[k] * inverse / r)
    scale = beta * inverse / r
    for j in range(n):
        row_k[j] = calA[k, j]
    for i in range(n):
        a_i = a_xq[i] * scale
        for j in range(n):
            calA[i, j] -= a_i * row_k[j]
    h_k = h[1 + k] - a_xq[k] * h_x * inverse
    for i in range(n):
        Ph[i] = h[1 + i] - a_xq[i] * h_x * inverse - scale * a_xq[i] * h_k
    for j in range(n):
        E[0, j] = (-calA[k, j] / r - a_xq[j]) * inverse
    e[0] = (-Ph[k] / r - h_x) * inverse


@njit(cache=True)
def _cholesky_solve(H: Array, rhs: Array, x: Array) -> bool:
    """``x = H^-1 rhs`` by Cholesky (``H = L L^T``); False when ``H`` is not positive
    definite."""
    n = len(rhs)
    L = np.empty((n, n))  # its lower triangle only is written and read
    inverse = np.empty(n)  # 1 / L[j, j]: products instead of divisions
    for j in range(n):
        d = H[j, j]
        for p in range(j):
            d -= L[j, p] * L[j, p]
        if not d > 0.0:
            return False
        L[j, j] = np.sqrt(d)
        inverse[j] = 1.0 / L[j, j]
        for i in range(j + 1, n):
            v = H[i, j]
            for p in range(j):
                v -= L[i, p] * L[j, p]
            L[i, j] = v * inverse[j]
    for i in range(n):
        v = rhs[i]
        for p in range(i):
            v -= L[i, p] * x[p]
        x[i] = v * inverse[i]
    for i in range(n - 1, -1, -1):
        v = x[i]
        for p in range(i + 1, n):
            v -= L[p, i] * x[p]
        x[i] = v * inverse[i]
    return True


@njit(cache=True)
def solution_terms_into(
    calA: Array,
    Ph: Array,
    actuator_map: Array,
    E: Array,
    e: Array,
    qdd: Array,
    generalized: Array,
    actuators: Array,
    nu_dot: Array,
) -> None:
    """What a solution ``qdd`` implies, into ``generalized``, ``actuators`` and ``nu_dot``: the
    generalised forces ``Gamma = calA qdd + Ph`` (eq. ``iso3``), the actuator torques
    ``M_act Gamma`` and ``nu_dot = E qdd + e``. The outputs must not be ``qdd`` (each is
    written while ``qdd`` is read)."""
    for i in range(len(Ph)):
        generalized[i] = row_dot(calA, i, qdd) + Ph[i]
    matvec_into(actuator_map, generalized, actuators)
    for i in range(len(e)):
        nu_dot[i] = row_dot(E, i, qdd) + e[i]


@njit(cache=True)
def solution_terms(
    calA: Array, Ph: Array, actuator_map: Array, E: Array, e: Array, qdd: Array
) -> tuple[Array, Array, Array]:
    """:func:`solution_terms_into`, into new arrays ``(generalized, actuators, nu_dot)``."""
    generalized, nu_dot = np.empty(len(Ph)), np.empty(len(e))
    actuators = np.empty(actuator_map.shape[0])
    solution_terms_into(calA, Ph, actuator_map, E, e, qdd, generalized, actuators, nu_dot)
    return generalized, actuators, nu_dot
