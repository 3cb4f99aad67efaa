"""Matrix products for the compiled (numba) arithmetic of the robot model and the low level.

numba's ``@`` calls BLAS and wants contiguous operands; these wrappers make transposes and
slices contiguous so that call sites read as the maths. Plain compiled loops were tried first
and measured slower at these sizes: ``T^T T`` (31 x 18), ``M_act calA`` (20 x 18 by 18 x 18)
and ``jac J_tf`` (6 x 30 by 30 x 19) took 20.7 us as loops against 4.2 us through BLAS, and the
QP kernel's arithmetic 29.5 us against 7.2 us (this 2-core machine, 2026-11-26).

Two exceptions. Operands of a few hundred entries (a 6 x 24 Jacobian times a velocity, 3 x 3
rotations) cost less as loops: a BLAS call's overhead is about 0.35 us here, the loops' 0.15 to
0.25 us (``small_matvec``, ``small_matmul``). And the products with ``J_tf``: it is mostly
zeros in a pattern fixed by the robot's layout (27 of 30 x 19 entries on KrangTray-v0's model),
and the ``*_pattern`` loops below visit only those entries. ``A = J_tf^T M J_tf`` took 6.2 to
10.4 us through BLAS and 2.8 us over the pattern (``minimal_dynamics``, same machine).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def matmul(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A @ B``."""
    return np.ascontiguousarray(A) @ np.ascontiguousarray(B)


@njit(cache=True)
def matvec(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A @ x``."""
    return np.ascontiguousarray(A) @ np.ascontiguousarray(x)


@njit(cache=True)
def gram(T: np.ndarray) -> np.ndarray:
    """``T^T T``."""
    return np.ascontiguousarray(T.T) @ T


@njit(cache=True)
def matvec_transposed(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A^T @ x``."""
    return np.ascontiguousarray(A.T) @ np.ascontiguousarray(x)


@njit(cache=True)
def matmul_transposed(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A^T @ B``."""
    return np.ascontiguousarray(A.T) @ np.ascontiguousarray(B)


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
