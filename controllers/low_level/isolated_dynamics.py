"""The isolated manipulator dynamics: paper eq. ``iso3`` (docs/ERRATA.md §4).

Eliminating ``xdd`` from the ``x`` row of ``A nu_dot + h = B ctrl`` leaves the body's own
equations

    Gamma = calA qdd + P h,     calA = (I - beta Bm) A*_qq,     P = (I - beta Bm) [-a_xq / a_xx, I]

with ``q`` every minimal coordinate but ``x`` (3-D: ``[psi, q1, ..., qn]``: ``psi`` joins ``q``,
driven by ``tau_0``; planar ``[q1, ..., qn]``), ``Gamma`` the generalised forces on ``q``
(``tau_0``, ``tau_1`` = the wheels' reaction on the base pitch, the joint torques),
``A*_qq = A_qq - a_xq a_xq^T / a_xx``, ``Bm = a_xq e_q1^T / (R a_xx)`` (called ``B`` in the
paper, a second meaning: docs/ERRATA.md §2), ``alpha = a_xq[q1] / (R a_xx)``, ``beta = 1 / (1 +
alpha)`` (Sherman-Morrison: no matrix is inverted). ``xdd`` follows from the ``x`` row:

    xdd = (-tau_1 / R - a_xq^T qdd - h_x) / a_xx

so every minimal acceleration is affine in ``qdd``: ``nu_dot = E qdd + e``, which is how task
Jacobians written over ``nu`` become rows of the QP over ``qdd``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]


@dataclass(frozen=True)
class IsolatedDynamics:
    """``Gamma = calA qdd + Ph`` and ``nu_dot = E qdd + e`` at one state.

    Attributes:
        calA: (n_q, n_q) the paper's script-A (not symmetric).
        Ph: (n_q,) ``P h``.
        E, e: the map from ``qdd`` to every minimal acceleration (x included).
        q_indices: indices of ``q`` in the minimal coordinates (all but ``x``).
        index_q1: position of ``q1`` inside ``q`` (0 planar, 1 in 3-D).
        index_psi: position of ``psi`` inside ``q`` (None planar).
    """

    calA: Array
    Ph: Array
    E: Array
    e: Array
    q_indices: Array
    index_q1: int
    index_psi: int | None

    def torques(self, qdd: Array) -> Array:
        """``Gamma`` for the accelerations ``qdd``."""
        return self.calA @ qdd + self.Ph


def isolated_dynamics(robot: RobotModel) -> IsolatedDynamics:
    """Eq. ``iso3`` from the robot's current ``A``, ``h`` (see the module docstring).

    ``x`` is the first minimal coordinate (``RobotLayout.index_x == 0``), so ``q`` is every
    later one and the blocks are slices (no index arrays, no copies)."""
    lay = robot.layout
    A, h = robot.A, robot.h
    n = lay.n_min
    if lay.index_x != 0:
        raise ValueError("isolated_dynamics expects x as the first minimal coordinate")
    a_xx = float(A[0, 0])
    a_xq = A[1:, 0]
    h_x, h_q = float(h[0]), h[1:]
    r = lay.wheel_radius
    k = lay.index_q1 - 1  # q1's place inside q (x removed)
    # A* = A_qq - a_xq a_xq^T / a_xx (outer products by broadcasting: np.outer's arithmetic,
    # without its overhead; temporaries updated in place)
    outer = a_xq[:, None] * a_xq
    outer /= a_xx
    A_star = A[1:, 1:] - outer
    alpha = float(a_xq[k]) / (r * a_xx)
    beta = 1.0 / (1.0 + alpha)
    # (I - beta Bm) M = M - beta a_xq M[k] / (R a_xx), Bm = a_xq e_k^T / (R a_xx)
    scale = beta / (r * a_xx)
    outer = np.multiply(a_xq[:, None], A_star[k], out=outer)
    outer *= scale
    calA = A_star - outer
    h_star = h_q - a_xq * h_x / a_xx
    Ph = h_star - scale * a_xq * float(h_star[k])
    # xdd = (-tau_1 / R - a_xq^T qdd - h_x) / a_xx with tau_1 = calA[k] qdd + Ph[k]
    E = _shift(n).copy()
    e = np.zeros(n)
    E[0] = (-calA[k] / r - a_xq) / a_xx
    e[0] = (-float(Ph[k]) / r - h_x) / a_xx
    index_psi = None if lay.index_psi is None else lay.index_psi - 1
    return IsolatedDynamics(
        calA=calA, Ph=Ph, E=E, e=e, q_indices=_q_indices(n), index_q1=k, index_psi=index_psi
    )


_Q_INDICES: dict[int, Array] = {}
_SHIFTS: dict[int, Array] = {}


def _shift(n: int) -> Array:
    """``np.eye(n, n - 1, k=-1)`` (E's rows below x), made once per size, read-only."""
    if n not in _SHIFTS:
        shift = np.eye(n, n - 1, k=-1)
        shift.flags.writeable = False
        _SHIFTS[n] = shift
    return _SHIFTS[n]


def _q_indices(n: int) -> Array:
    """``[1, ..., n - 1]``, made once per size, read-only."""
    if n not in _Q_INDICES:
        indices = np.arange(1, n)
        indices.flags.writeable = False
        _Q_INDICES[n] = indices
    return _Q_INDICES[n]
