"""The arithmetic of ``RobotModel.update`` after its MuJoCo calls, compiled by numba.

Two functions of arrays (``wip_gym.robot_model`` makes the MuJoCo calls and keeps the results):

* :func:`minimal_dynamics`: paper eq. ``dyn``, ``A = J_tf^T M J_tf``,
  ``h = J_tf^T (M Jdot_tf nu + c - f_passive)``, ``B = J_tf^T S``;
* :func:`body_com`: the body's CoM (wheels excluded) in the axle frame, its Jacobian over
  ``nu``, ``theta = atan2(X, Z)`` and ``J_theta``, ``thetad = J_theta nu``.

The NumPy expressions they replace are kept in ``tests/test_robot_model.py`` and compared on
random states of every robot.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from wip_gym.small_linalg import matmul, matmul_transposed, matvec, matvec_transposed


@njit(cache=True)
def minimal_dynamics(
    M: np.ndarray,
    J: np.ndarray,
    Jdot_nu: np.ndarray,
    bias: np.ndarray,
    passive: np.ndarray,
    S: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(A, h, B)`` of paper eq. ``dyn`` (new arrays)."""
    A = matmul_transposed(J, matmul(M, J))
    h = matvec_transposed(J, matvec(M, Jdot_nu) + bias - passive)
    B = matmul_transposed(J, S)
    return A, h, B


@njit(cache=True)
def body_com(
    masses: np.ndarray,
    positions: np.ndarray,
    origin: np.ndarray,
    jac_subtree: np.ndarray,
    subtree_mass: float,
    wheel_masses: np.ndarray,
    jac_wheels: np.ndarray,
    jac_origin: np.ndarray,
    J: np.ndarray,
    nu: np.ndarray,
    c: float,
    s: float,
    planar: bool,
) -> tuple[float, np.ndarray, np.ndarray, float, float, np.ndarray]:
    """``(mass, com, J_com, theta, thetad, J_theta)`` of the body (every robot body but the
    wheels: ``masses``, ``positions`` their CoMs in world) about the axle ``origin``, in the
    axle frame (``Rz(psi)``, ``c``, ``s``; the world's when planar). ``J_com`` from the base
    subtree's CoM Jacobian less the wheels', relative to the origin's, over ``nu`` (``J``);
    in 3-D the frame's turning adds ``-psid e_z x com`` (column 1, ``psi``)."""
    mass = 0.0
    for i in range(len(masses)):
        mass += masses[i]
    world = np.zeros(3)
    for i in range(len(masses)):
        for a in range(3):
            world[a] += masses[i] * positions[i, a]
    world /= mass
    offset = world - origin
    Jc = jac_subtree * subtree_mass
    for w in range(len(wheel_masses)):
        Jc -= wheel_masses[w] * jac_wheels[w]
    Jc /= mass
    J_rel = matmul(Jc - jac_origin, J)
    if planar:
        com = offset
    else:
        com = np.empty(3)
        com[0] = c * offset[0] + s * offset[1]
        com[1] = -s * offset[0] + c * offset[1]
        com[2] = offset[2]
        rotated = np.empty_like(J_rel)
        rotated[0] = c * J_rel[0] + s * J_rel[1]
        rotated[1] = -s * J_rel[0] + c * J_rel[1]
        rotated[2] = J_rel[2]
        J_rel = rotated
        J_rel[0, 1] += com[1]
        J_rel[1, 1] -= com[0]
    X, Z = com[0], com[2]
    theta = math.atan2(X, Z)
    distance_sq = X * X + Z * Z
    if distance_sq > 1e-18:
        J_theta = (Z * J_rel[0] - X * J_rel[2]) / distance_sq
    else:
        J_theta = np.zeros(J_rel.shape[1])
    thetad = 0.0
    for i in range(len(nu)):
        thetad += J_theta[i] * nu[i]
    return mass, com, J_rel, theta, thetad, J_theta
