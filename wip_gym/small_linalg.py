"""Matrix products for the low level's small arrays, as plain loops compiled by numba.

A BLAS call costs about a microsecond before any arithmetic; the low level's products are a few
hundred to a few thousand multiply-adds (Krang: 6 x 24 by 24 x 18), which a compiled loop does in
less. The sums run in index order; they differ from BLAS's by rounding only (tested against
NumPy in ``tests/test_compiled_tasks.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def matmul(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A @ B``."""
    n, k = A.shape
    m = B.shape[1]
    out = np.zeros((n, m))
    for i in range(n):
        for p in range(k):
            a = A[i, p]
            if a != 0.0:
                for j in range(m):
                    out[i, j] += a * B[p, j]
    return out


@njit(cache=True)
def matvec(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A @ x``."""
    n, k = A.shape
    out = np.zeros(n)
    for i in range(n):
        total = 0.0
        for p in range(k):
            total += A[i, p] * x[p]
        out[i] = total
    return out


@njit(cache=True)
def gram(T: np.ndarray) -> np.ndarray:
    """``T^T T`` (symmetric: each entry summed once)."""
    rows, n = T.shape
    out = np.zeros((n, n))
    for i in range(n):
        for j in range(i, n):
            total = 0.0
            for r in range(rows):
                total += T[r, i] * T[r, j]
            out[i, j] = total
            out[j, i] = total
    return out


@njit(cache=True)
def matvec_transposed(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A^T @ x``."""
    k, n = A.shape
    out = np.zeros(n)
    for p in range(k):
        value = x[p]
        for i in range(n):
            out[i] += A[p, i] * value
    return out


@njit(cache=True)
def matmul_transposed(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A^T @ B``."""
    k, n = A.shape
    m = B.shape[1]
    out = np.zeros((n, m))
    for p in range(k):
        for i in range(n):
            a = A[p, i]
            if a != 0.0:
                for j in range(m):
                    out[i, j] += a * B[p, j]
    return out
