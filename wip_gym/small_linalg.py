"""Matrix products for the compiled (numba) arithmetic of the robot model and the low level.

At these sizes (tens of rows and columns) a call's overhead and the operands' zeros decide,
not the flops: numba's ``@`` calls BLAS (about 0.35 us per call here, plus a contiguous copy
of a transposed operand and a new array for the result), and the low level's operands are
mostly zeros in a pattern fixed for a run.

* The products with ``J_tf``: it is mostly zeros in a pattern fixed by the robot's layout (27
  of 30 x 19 entries on KrangTray-v0's model), and the ``*_pattern`` loops below visit only
  those entries. ``A = J_tf^T M J_tf`` took 6.2 to 10.4 us through BLAS and 2.8 us over the
  pattern (2026-11-26); the robot update now runs the same sums in its own loops, in place
  (``wip_gym.minimal_kernels.minimal_dynamics_into``), and the tests use these as its
  reference.
* The QP kernel's (``controllers.low_level.kernel``): the task matrix ``T`` has a posture row
  of one entry per joint (16 of KrangTray-v0's 30 rows), the actuator map one or two entries
  per row. Loops in the operands' memory order that skip zero entries (``gram_into``,
  ``matmul_into``) took 0.53 us for ``T^T T`` against 1.03 through BLAS and 0.19 against 0.66
  for ``M_act calA``, and the matrix-vector loops (``row_dot``, ``matvec_into``,
  ``matvec_transposed_into``) 0.09 to 0.15 us against 0.17 to 0.37; they write into the
  caller's buffers. Plain loops tried first were slower than BLAS:
  20.7 us against 4.2 for ``T^T T``, ``M_act calA`` and ``jac J_tf`` (2026-11-26).
* Operands of a few hundred entries (3 x 3 rotations): ``small_matmul`` (0.15 to 0.25 us
  against BLAS's 0.35).

``small_matvec`` and the ``*_pattern`` products are the robot update's arithmetic before it
wrote in place: the tests hold ``minimal_dynamics_into`` to them, to the bit.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def gram_into(T: np.ndarray, out: np.ndarray) -> None:
    """``out = T^T T``, row by row of ``T``, skipping its zero entries (a row of one entry
    adds to one row of ``out``). A NaN in ``T`` reaches the diagonal of ``out``; with an inf,
    ``out`` may not be symmetric (``0 * inf`` terms are skipped): callers test the result for
    finiteness, as the kernel does its minimiser."""
    out[:] = 0.0
    rows, n = T.shape
    for k in range(rows):
        for i in range(n):
            t = T[k, i]
            if t != 0.0:
                for j in range(n):
                    out[i, j] += t * T[k, j]


@njit(cache=True)
def matmul_into(A: np.ndarray, B: np.ndarray, out: np.ndarray) -> None:
    """``out = A @ B``, skipping the zero entries of ``A`` (so a NaN or inf in a row of ``B``
    that no entry of ``A`` reaches stays out of ``out``, where ``A @ B`` would give NaN)."""
    out[:] = 0.0
    for i in range(A.shape[0]):
        for k in range(A.shape[1]):
            a = A[i, k]
            if a != 0.0:
                for j in range(B.shape[1]):
                    out[i, j] += a * B[k, j]


@njit(cache=True)
def row_dot(A: np.ndarray, i: int, x: np.ndarray) -> float:
    """``A[i] @ x``."""
    total = 0.0
    for k in range(A.shape[1]):
        total += A[i, k] * x[k]
    return total


@njit(cache=True)
def matvec_into(A: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    """``out = A @ x`` (``out`` not ``x``)."""
    for i in range(A.shape[0]):
        out[i] = row_dot(A, i, x)


@njit(cache=True)
def matvec_transposed_into(A: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    """``out = A^T @ x`` over ``A``'s rows, its memory order (``out`` not ``x``)."""
    out[:] = 0.0
    for i in range(A.shape[0]):
        xi = x[i]
        for j in range(A.shape[1]):
            out[j] += A[i, j] * xi


@njit(cache=True)
def matmul_pattern(A: np.ndarray, S: np.ndarray, pattern: np.ndarray) -> np.ndarray:
    """``A @ S`` for an ``S`` whose nonzero entries all lie in ``pattern`` (``(2, nnz)``: row
    and column indices, each entry once: a repeated one would count twice): ``rows(A) x nnz``
    multiply-adds instead of ``rows(A) x size(S)``."""
    out = np.zeros((A.shape[0], S.shape[1]))
    for e in range(pattern.shape[1]):
        r, c = pattern[0, e], pattern[1, e]
        value = S[r, c]
        for i in range(A.shape[0]):
            out[i, c] += A[i, r] * value
    return out


@njit(cache=True)
def matmul_transposed_pattern(S: np.ndarray, pattern: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``S^T @ B`` for an ``S`` whose nonzero entries all lie in ``pattern``
    (:func:`matmul_pattern`)."""
    out = np.zeros((S.shape[1], B.shape[1]))
    for e in range(pattern.shape[1]):
        r, c = pattern[0, e], pattern[1, e]
        value = S[r, c]
        for j in range(B.shape[1]):
            out[c, j] += value * B[r, j]
    return out


@njit(cache=True)
def matvec_transposed_pattern(S: np.ndarray, pattern: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``S^T @ x`` for an ``S`` whose nonzero entries all lie in ``pattern``
    (:func:`matmul_pattern`)."""
    out = np.zeros(S.shape[1])
    for e in range(pattern.shape[1]):
        r, c = pattern[0, e], pattern[1, e]
        out[c] += S[r, c] * x[r]
    return out


@njit(cache=True)
def small_matvec(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A @ x`` as a loop (operands of a few hundred entries: module docstring)."""
    out = np.empty(A.shape[0])
    for i in range(A.shape[0]):
        total = 0.0
        for k in range(A.shape[1]):
            total += A[i, k] * x[k]
        out[i] = total
    return out


@njit(cache=True)
def small_matmul(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A @ B`` as a loop (operands of a few hundred entries: module docstring)."""
    out = np.zeros((A.shape[0], B.shape[1]))
    for i in range(A.shape[0]):
        for k in range(A.shape[1]):
            a = A[i, k]
            for j in range(B.shape[1]):
                out[i, j] += a * B[k, j]
    return out
