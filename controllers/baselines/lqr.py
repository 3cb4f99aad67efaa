"""Discrete-time LQR at the control step, from continuous-time linearisations."""

from __future__ import annotations

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

Array = NDArray[np.float64]


def zero_order_hold(A: Array, B: Array, dt: float) -> tuple[Array, Array]:
    """Exact discretisation of ``xdot = A x + B u`` with ``u`` held over ``dt``."""
    n, m = B.shape
    block = np.zeros((n + m, n + m))
    block[:n, :n] = A
    block[:n, n:] = B
    phi = scipy.linalg.expm(block * dt)
    return phi[:n, :n], phi[:n, n:]


def uncontrollable_modes(A: Array, B: Array, tol: float = 1e-8) -> list[complex]:
    """Eigenvalues ``l`` of ``A`` with ``rank [A - l I, B] < n`` (the PBH test; unlike the
    Krylov matrix it stays well scaled for a discrete model at a 1 ms step)."""
    n = A.shape[0]
    modes = []
    for eigenvalue in np.linalg.eigvals(A):
        pencil = np.hstack([A - eigenvalue * np.eye(n), B])
        s = np.linalg.svd(pencil, compute_uv=False)
        if s[-1] <= tol * max(s[0], 1.0):
            modes.append(complex(eigenvalue))
    return modes


def dlqr(Ad: Array, Bd: Array, Q: Array, R: Array) -> tuple[Array, Array]:
    """Gain ``K`` (``u = -K x``) and the Riccati solution ``P`` of the discrete LQR.

    Raises ``ValueError`` when ``(Ad, Bd)`` has an uncontrollable mode on or outside the unit
    circle or the Riccati equation has no stabilising solution, e.g. a posture whose
    linearisation loses the wheels' authority."""
    bad = [m for m in uncontrollable_modes(Ad, Bd) if abs(m) >= 1.0 - 1e-12]
    if bad:
        raise ValueError(
            "LQR problem ill-posed: the linearised model is not stabilisable at this posture "
            f"(uncontrollable modes {bad})"
        )
    try:
        P = scipy.linalg.solve_discrete_are(Ad, Bd, Q, R)
    except (np.linalg.LinAlgError, ValueError) as error:
        raise ValueError(
            f"LQR problem ill-posed: no stabilising Riccati solution ({error})"
        ) from None
    K = np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)
    return K, P
