"""The wheel-torque map ``(tau_L, tau_R) <-> (tau_0, tau_1)`` (paper eq. ``tau01``,
docs/ERRATA.md §3).

Convention (one, used everywhere in wip-gym): ``tau_0`` is the **generalised force on the
heading** ``psi`` and ``tau_1`` the generalised force the wheel motors put on the base pitch
``q1`` (their reaction). With the wheel hinges about +y (a positive motor torque rolls the
wheel forward), the wheels at ``y = +-separation/2`` and radius ``r``:

    tau_0 = separation / (2 r) * (tau_R - tau_L)
    tau_1 = -(tau_L + tau_R)

and the forward coordinate ``x`` feels ``(tau_L + tau_R) / r = -tau_1 / r``. The paper's eq.
``tau01`` prints ``tau_0`` with the opposite sign; ``B_bar``'s second row agrees with ours.
Both directions are tested against MuJoCo's actuation projected by ``J_tf``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def wheel_to_generalized(
    tau_left: ArrayLike, tau_right: ArrayLike, wheel_radius: float, wheel_separation: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(tau_L, tau_R) -> (tau_0, tau_1)``: spin force on ``psi`` and pitch torque on ``q1``."""
    tau_left = np.asarray(tau_left, dtype=float)
    tau_right = np.asarray(tau_right, dtype=float)
    tau_0 = wheel_separation / (2.0 * wheel_radius) * (tau_right - tau_left)
    tau_1 = -(tau_left + tau_right)
    return tau_0, tau_1


def generalized_to_wheel(
    tau_0: ArrayLike, tau_1: ArrayLike, wheel_radius: float, wheel_separation: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(tau_0, tau_1) -> (tau_L, tau_R)``, the inverse of :func:`wheel_to_generalized`."""
    tau_0 = np.asarray(tau_0, dtype=float)
    tau_1 = np.asarray(tau_1, dtype=float)
    difference = 2.0 * wheel_radius / wheel_separation * tau_0  # tau_R - tau_L
    tau_left = 0.5 * (-tau_1 - difference)
    tau_right = 0.5 * (-tau_1 + difference)
    return tau_left, tau_right


def generalized_to_wheel_matrix(
    wheel_radius: float, wheel_separation: float
) -> NDArray[np.float64]:
    """The 2x2 matrix ``W`` with ``[tau_L, tau_R] = W @ [tau_0, tau_1]`` (for QP constraints)."""
    k = wheel_radius / wheel_separation
    return np.array([[-k, -0.5], [k, -0.5]])
