"""Matrix products for the compiled (numba) arithmetic of the robot model and the low level.

numba's ``@`` calls BLAS and wants contiguous operands; these wrappers make transposes and
slices contiguous so that call sites read as the maths. Plain compiled loops were tried first
and measured slower at these sizes: ``T^T T`` (31 x 18), ``M_act calA`` (20 x 18 by 18 x 18)
and ``jac J_tf`` (6 x 30 by 30 x 18) took 20.7 us as loops against 4.2 us through BLAS, and the
QP kernel's arithmetic 29.5 us against 7.2 us (this 2-core machine, 2026-11-26).
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
