"""The wheeled inverted pendulum model (WIPM): the paper's simplified model, in JAX.

The whole robot lumped into one rigid body (mass ``M``, CoM at distance ``L`` from the axle) on
two wheels, with the parameters ``lambda(q)`` of the current pose (paper section "Simplified
Model"; :func:`params_from_lambda`). Pure, jit-friendly functions in the style of trajax:
``dynamics(s, u, params) -> sdot`` in continuous time, with :func:`discretize` for the paper's
explicit-Euler steps and :func:`linearize` for the Jacobians.

Planar model (state ``s = [theta, thetad, x, xd]``), docs/ERRATA.md §1. The two rows of the one-link
WIP, with ``m_w``, ``I_w`` the mass and axial inertia of BOTH wheels, ``I`` the body's pitch inertia
about the axle, ``tau_w = tau_L + tau_R`` the total wheel torque and ``d`` one wheel joint's
viscous damping (acting on the wheel's rotation relative to the body, ``xd / R - thd``):

    x row:  (m_w + I_w/R^2 + M) xdd + M L cos th thdd - M L sin th thd^2
                = tau_w / R - 2 d (xd/R - thd) / R
    th row: M L cos th xdd + I thdd - M g L sin th = -tau_w + 2 d (xd/R - thd)

``R * (x row) + (th row)`` eliminates the torque (and the damping with it) and gives the zero
dynamics, paper eqs. ``WIPzero`` / ``WIPdyn`` as corrected by docs/ERRATA.md §1:

    (alpha + cos th) xdd + (beta + R cos th) thdd = g sin th + R sin th thd^2
    alpha = R (M + m_w + I_w/R^2) / (M L),   beta = I / (M L)

The paper's printed form (``beta + cos th`` and ``- R sin th thd^2``) is wrong by order
10 m/s^2 on random states; ``tests/test_wipm.py`` writes it out and shows it.

3-D model (state ``s = [x, psi, theta, xd, psid, thetad, X0, Y0]``), the structure of the
authors' Krang3D model (docs/AUTHORS_CONFIG.md §2.1-2.4) but derived here exactly, by Kane's
method. ``xd`` (the axle's forward speed) is a quasi-velocity, so a Lagrangian in ``x`` is not
exact; instead, with ``nu = [xd, psid, thetad]`` and the rolling/no-side-slip constraints built
into the velocities of the three rigid bodies (the lumped body and the two wheels),

    A(q) nu_dot + h(q, nu) = B [tau_L, tau_R]
    A = sum_i J_i^T M_i J_i
    h = sum_i J_i^T (M_i Jdot_i nu + [0; w_i x I_i w_i]) - Q_gravity - Q_damping

(``J_i`` the Jacobian of body ``i``'s twist ``[v_com; omega]`` with respect to ``nu``). The
vectors are taken in heading-frame components, where the problem depends on ``theta`` only; the
world-frame rate of a vector is ``dv/dt|_heading + psid e_z x v``, and ``Jdot_i nu`` follows
exactly from ``jax.jvp`` of ``J_i(theta) nu`` along ``thetad`` plus that transport term. The
contact forces do no work and drop out. The wheels' rotation relative to the body is
``phi_dot - thetad`` with ``phi_dot = (xd -+ sep/2 psid)/R`` (left/right), so a motor torque (and
each joint's damping ``-d (phi_dot - thetad)``) enters through the column
``[1/R, -+sep/(2R), -1]``: ``B [tau_L, tau_R] = [(tau_L + tau_R)/R, tau_0, tau_1]`` with
``tau_0 = sep/(2R) (tau_R - tau_L)`` the generalised force on ``psi`` (docs/ERRATA.md §3;
wip_gym.wheel_torques) and ``tau_1 = -(tau_L + tau_R)`` the torque on the body pitch (paper
eq. ``dyn``, ``simple1``/``simple2`` for the lumped model).

That derivation is kept as the reference, :func:`spatial_equations_kane`; the model itself uses
its closed form (:func:`spatial_terms`, derived symbolically from it and tested against it to
round-off), plain scalar arithmetic that is far cheaper to compile and to differentiate inside a
DDP. ``A`` depends on ``theta`` only, ``h`` on ``theta`` and ``nu`` (not on ``x``, ``psi``,
``X0``, ``Y0``); with ``J`` the body's inertia about the axle midpoint in its CoM frame,

    A = [[M + 2 m_r,   -M c_y,                                 M L cos th         ],
         [-M c_y,      J_xx s^2 + J_zz c^2 - 2 J_xz s c + C,   J_yz c - J_xy s    ],
         [M L cos th,  J_yz c - J_xy s,                        J_yy               ]]

(``m_r = m_w + I_a/R^2`` one wheel's rolling mass, ``C = 2 ((sep/2)^2 m_r + I_t)``), and ``h``
as given in :func:`spatial_terms`.

With the pitch acceleration ``thdd`` as control (the MPC's ``u = [thdd, tau_0]``),
:func:`spatial_dynamics` eliminates ``tau_1`` by ``R * (x row) + (theta row)`` and keeps the
``psi`` row with ``tau_0``; :func:`inverse_dynamics` recovers the wheel torques.

Conventions (wip_gym.robot_model): x forward, y left, z up; ``psi`` the heading; ``theta`` the
pitch of the body CoM about the axle, ``atan2(X_com, Z_com)`` in the axle frame, positive with the
CoM ahead; wheels at ``y = +-separation/2``, hinges about +y, a positive wheel torque rolls
forward. The wheels are taken axisymmetric (one transverse inertia). The functions are not jitted
here: wrap them (``jax.jit(spatial_dynamics)``, ``jax.jit(linearize, static_argnums=0)``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

if TYPE_CHECKING:
    from wip_gym.robot_model import RobotModel, WIPMParameters

Array = jax.Array
ArrayLike = jax.typing.ArrayLike
Dynamics = Callable[[Array, Array, "WIPMParams"], Array]


class WIPMParams(NamedTuple):
    """The WIPM's parameters ``lambda(q)`` (a pytree of floats/arrays).

    Attributes:
        body_mass: ``M``, everything but the wheels (kg).
        com_distance: ``L``, distance of the body CoM from the axle in the sagittal x-z plane (m).
        com_lateral: the CoM's y offset in the axle frame (m).
        inertia_body: 3x3, the body's inertia tensor about the axle midpoint in the body's CoM
            frame ``B`` (the axle frame rotated about y by ``theta``: the CoM is at
            ``(0, com_lateral, com_distance)`` in ``B``). ``inertia_body[1, 1]`` is ``I``, the
            pitch inertia about the axle.
        wheel_mass: mass of ONE wheel (kg).
        wheel_inertia: axial inertia of ONE wheel (kg m^2).
        wheel_inertia_transverse: inertia of ONE wheel about a diameter (kg m^2).
        wheel_damping: viscous damping of ONE wheel joint (N m s/rad), on the wheel's rotation
            relative to the body.
        wheel_radius: ``R`` (m).
        wheel_separation: distance between the wheels (the paper's other ``L``, docs/ERRATA.md §2)
            (m).
        gravity: ``g`` (m/s^2, positive).
    """

    body_mass: ArrayLike
    com_distance: ArrayLike
    com_lateral: ArrayLike
    inertia_body: ArrayLike
    wheel_mass: ArrayLike
    wheel_inertia: ArrayLike
    wheel_inertia_transverse: ArrayLike
    wheel_damping: ArrayLike
    wheel_radius: ArrayLike
    wheel_separation: ArrayLike
    gravity: ArrayLike


def rotation_y(angle: ArrayLike) -> Array:
    """``Ry(angle)``, the rotation about +y: ``Ry(theta) @ (0, 0, L) = (L sin theta, 0, L cos
    theta)``, i.e. the axle-frame coordinates of a point given in the body CoM frame ``B``."""
    c, s = jnp.cos(angle), jnp.sin(angle)
    zero, one = jnp.zeros_like(c), jnp.ones_like(c)
    return jnp.array([[c, zero, s], [zero, one, zero], [-s, zero, c]])


def params_from_lambda(p: WIPMParameters) -> WIPMParams:
    """The WIPM parameters from ``lambda(q)`` (``RobotModel.wipm_parameters()``) at one state.

    The body inertia about the axle midpoint is rotated from the axle frame into the CoM frame
    ``B`` (axle frame rotated about y by ``theta``): ``I_B = Ry(theta)^T I_axle Ry(theta)``, so
    that ``Ry(theta)^T com = (0, com_lateral, com_distance)``. Its ``[1, 1]`` entry is the pitch
    inertia ``I`` (rotation about y leaves it unchanged).
    """
    theta = float(p.theta)
    c, s = np.cos(theta), np.sin(theta)
    rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])  # rotation_y, in NumPy
    inertia_body = rot.T @ np.asarray(p.inertia_axle, dtype=float) @ rot
    inertia_body = 0.5 * (inertia_body + inertia_body.T)

    # NumPy values (called once per MPC step, outside jit: eager JAX would cost milliseconds)
    def f(value: float) -> np.float64:
        return np.float64(value)

    return WIPMParams(
        body_mass=f(p.body_mass),
        com_distance=f(p.com_distance),
        com_lateral=f(p.com[1]),
        inertia_body=inertia_body,
        wheel_mass=f(p.wheel_mass),
        wheel_inertia=f(p.wheel_inertia),
        wheel_inertia_transverse=f(p.wheel_inertia_transverse),
        wheel_damping=f(p.wheel_damping),
        wheel_radius=f(p.wheel_radius),
        wheel_separation=f(p.wheel_separation),
        gravity=f(p.gravity),
    )


def params_from_robot(robot: RobotModel) -> WIPMParams:
    """:func:`params_from_lambda` of ``robot.wipm_parameters()`` at the robot's last update, in
    one compiled call (``RobotModel.wipm_values``), once per MPC step. KrangTray-v0 after 300
    steps, medians on this 2-core machine shared with another job: 7 us against 67 us in a
    tight loop, 18 us against 123 us per MPC tick in the closed loop (cold caches; 2026-11-26).

    The same values, to round-off (``tests/test_wipm.py``), and the same leaves: NumPy float64
    scalars and a 3x3 float64 array, so that the jitted MPC step sees one signature whichever
    path made them. Masses and inertias are read from the model at this call (a payload or a
    randomised mass changed since the last call is seen).
    """
    values, inertia_body = robot.wipm_values()
    M, L, com_lateral, m_w, I_a, I_t, damping, R, sep, g = values  # WIPM_SCALARS' order
    f = np.float64
    return WIPMParams(
        f(M),
        f(L),
        f(com_lateral),
        inertia_body,
        f(m_w),
        f(I_a),
        f(I_t),
        f(damping),
        f(R),
        f(sep),
        f(g),
    )


def _solve2(A: Array, b: Array) -> Array:
    """``A^-1 b`` for a 2x2 ``A`` by Cramer's rule (small, well-conditioned systems; much
    cheaper to compile than a pivoted LU solve)."""
    det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
    return jnp.stack([A[1, 1] * b[0] - A[0, 1] * b[1], A[0, 0] * b[1] - A[1, 0] * b[0]]) / det


# --------------------------------------------------------------------------------- planar
def _planar_alpha_beta(params: WIPMParams) -> tuple[Array, Array]:
    M, L, R = params.body_mass, params.com_distance, params.wheel_radius
    m_w = 2.0 * params.wheel_mass
    I_w = 2.0 * params.wheel_inertia
    inertia = jnp.asarray(params.inertia_body)[1, 1]
    alpha = R * (M + m_w + I_w / R**2) / (M * L)
    beta = inertia / (M * L)
    return alpha, beta


def planar_dynamics(s: ArrayLike, u: ArrayLike, params: WIPMParams) -> Array:
    """Planar WIPM zero dynamics with the pitch acceleration as control (paper eq. ``WIPdyn``,
    ``f_c`` from eq. ``WIPzero``, corrected per docs/ERRATA.md §1).

    ``s = [theta, thetad, x, xd]``, ``u = thdd`` (scalar or shape ``(1,)``). Returns
    ``sdot = [thd, thdd, xd, xdd]`` with

        xdd = (g sin th + R sin th thd^2 - (beta + R cos th) thdd) / (alpha + cos th).

    The wheel torque and the wheel damping cancel out of ``R * (x row) + (th row)``.
    """
    s = jnp.asarray(s)
    thdd = jnp.reshape(jnp.asarray(u), (-1,))[0]
    th, thd, xd = s[0], s[1], s[3]
    R, g = params.wheel_radius, params.gravity
    alpha, beta = _planar_alpha_beta(params)
    c, sn = jnp.cos(th), jnp.sin(th)
    xdd = (g * sn + R * sn * thd**2 - (beta + R * c) * thdd) / (alpha + c)
    return jnp.stack([thd, thdd, xd, xdd])


def _planar_rows(s: Array, params: WIPMParams) -> tuple[Array, Array, Array]:
    """Mass matrix ``A`` (rows x, th over ``[xdd, thdd]``), the right-hand side without the
    torque, and the torque column ``b``: ``A [xdd, thdd] = rhs + b tau_w`` (docs/ERRATA.md §1)."""
    th, thd, xd = s[0], s[1], s[3]
    M, L, R, g = params.body_mass, params.com_distance, params.wheel_radius, params.gravity
    m_w = 2.0 * params.wheel_mass
    I_w = 2.0 * params.wheel_inertia
    inertia = jnp.asarray(params.inertia_body)[1, 1]
    c, sn = jnp.cos(th), jnp.sin(th)
    relative = xd / R - thd  # each wheel's rotation rate relative to the body
    damping = 2.0 * params.wheel_damping * relative  # both wheels' damping torque magnitude
    A = jnp.array([[m_w + I_w / R**2 + M, M * L * c], [M * L * c, inertia]])
    rhs = jnp.stack([M * L * sn * thd**2 - damping / R, M * g * L * sn + damping])
    b = jnp.stack([1.0 / R, -1.0])
    return A, rhs, b


def planar_torque_dynamics(s: ArrayLike, tau_w: ArrayLike, params: WIPMParams) -> Array:
    """Planar WIPM with the total wheel torque ``tau_w = tau_L + tau_R`` as input (the x and th
    rows of docs/ERRATA.md §1 before the torque is eliminated, with the wheels' viscous damping).

    ``s = [theta, thetad, x, xd]``; returns ``[thd, thdd, xd, xdd]``.
    """
    s = jnp.asarray(s)
    tau = jnp.reshape(jnp.asarray(tau_w), (-1,))[0]
    A, rhs, b = _planar_rows(s, params)
    xdd, thdd = _solve2(A, rhs + b * tau)
    return jnp.stack([s[1], thdd, s[3], xdd])


def planar_inverse_dynamics(s: ArrayLike, u: ArrayLike, params: WIPMParams) -> Array:
    """The total wheel torque ``tau_w = tau_L + tau_R`` that gives the pitch acceleration
    ``u = thdd`` at state ``s = [theta, thetad, x, xd]`` (the th row, with ``xdd`` from
    :func:`planar_dynamics`)."""
    s = jnp.asarray(s)
    sdot = planar_dynamics(s, u, params)
    A, rhs, _ = _planar_rows(s, params)
    acc = jnp.stack([sdot[3], sdot[1]])
    return -(A[1] @ acc - rhs[1])


# ------------------------------------------------------------------------------------ 3-D
class SpatialTerms(NamedTuple):
    """The scalar entries of :func:`spatial_equations`' ``A`` (symmetric: the upper triangle)
    and ``h``, rows and columns ``[x, psi, theta]``."""

    a_xx: Array
    a_xp: Array
    a_xt: Array
    a_pp: Array
    a_pt: Array
    a_tt: Array
    h_x: Array
    h_p: Array
    h_t: Array


def spatial_terms(s: ArrayLike, params: WIPMParams) -> SpatialTerms:
    """The closed form of the 3-D WIPM's ``A`` and ``h`` (see :func:`spatial_equations`), as
    scalars: ``sin``/``cos`` of ``theta`` once and a few products, no matrices.

    With ``J = inertia_body`` (about the axle midpoint, CoM frame ``B``; symmetric), ``c, s`` the
    cosine and sine of ``theta``, ``m_r = m_w + I_a/R^2`` one wheel's rolling mass and ``k =
    sep/2``:

        a_xx = M + 2 m_r        a_xp = -M c_y        a_xt = M L c        a_tt = J_yy
        a_pp = J_xx s^2 + J_zz c^2 - 2 J_xz s c + 2 (k^2 m_r + I_t)
        a_pt = J_yz c - J_xy s
        p    = (J_xx - J_zz) s c - J_xz (c^2 - s^2)     (= 1/2 d a_pp / d theta)
        h_x  = -M L s (thd^2 + psid^2) + 2 d (xd/R - thd) / R
        h_p  = M L s xd psid + 2 p psid thd - (J_xy c + J_yz s) thd^2 + 2 d k^2 psid / R^2
        h_t  = -M g L s - p psid^2 - 2 d (xd/R - thd)

    (``d`` the damping of one wheel joint; ``-(J_xy c + J_yz s) = d a_pt / d theta``). The
    lateral CoM offset enters only through ``a_xp``, the wheels' transverse inertia only through
    ``a_pp``. Derived from :func:`spatial_equations_kane` symbolically and checked against it
    (tests/test_wipm.py).
    """
    s = jnp.asarray(s)
    theta, xd, psid, thd = s[2], s[3], s[4], s[5]
    M, L, R, g = params.body_mass, params.com_distance, params.wheel_radius, params.gravity
    J = jnp.asarray(params.inertia_body)
    J_xx, J_xy, J_xz, J_yy, J_yz, J_zz = J[0, 0], J[0, 1], J[0, 2], J[1, 1], J[1, 2], J[2, 2]
    c, sn = jnp.cos(theta), jnp.sin(theta)
    cc, ss, sc = c * c, sn * sn, sn * c
    k = 0.5 * params.wheel_separation
    rolling_mass = params.wheel_mass + params.wheel_inertia / R**2  # one wheel's
    ML_s = M * L * sn
    p = (J_xx - J_zz) * sc - J_xz * (cc - ss)
    damping = 2.0 * params.wheel_damping * (xd / R - thd)  # both joints', on x and theta
    a_pp = (
        J_xx * ss
        + J_zz * cc
        - 2.0 * J_xz * sc
        + 2.0 * (k * k * rolling_mass + params.wheel_inertia_transverse)
    )
    h_p = (
        ML_s * xd * psid
        + 2.0 * p * psid * thd
        - (J_xy * c + J_yz * sn) * thd * thd
        + 2.0 * params.wheel_damping * (k / R) ** 2 * psid
    )
    return SpatialTerms(
        a_xx=M + 2.0 * rolling_mass,
        a_xp=-M * params.com_lateral,
        a_xt=M * L * c,
        a_pp=a_pp,
        a_pt=J_yz * c - J_xy * sn,
        a_tt=J_yy,
        h_x=-ML_s * (thd * thd + psid * psid) + damping / R,
        h_p=h_p,
        h_t=-ML_s * g - p * psid * psid - damping,
    )


def spatial_equations(s: ArrayLike, params: WIPMParams) -> tuple[Array, Array, Array]:
    """The 3-D WIPM's equations ``A nu_dot + h = B [tau_L, tau_R]`` over
    ``nu = [xd, psid, thetad]`` at state ``s = [x, psi, theta, xd, psid, thetad, X0, Y0]``, in
    closed form (:func:`spatial_terms`; the same equations as :func:`spatial_equations_kane`, to
    round-off). ``A`` depends on ``theta`` only, ``h`` on ``theta`` and ``nu``; ``x``, ``psi``,
    ``X0``, ``Y0`` do not enter. Returns ``(A, h, B)`` with ``B`` from
    :func:`wheel_torque_matrix`.
    """
    t = spatial_terms(s, params)
    A = jnp.stack(
        [
            jnp.stack([t.a_xx, t.a_xp, t.a_xt]),
            jnp.stack([t.a_xp, t.a_pp, t.a_pt]),
            jnp.stack([t.a_xt, t.a_pt, t.a_tt]),
        ]
    )
    return A, jnp.stack([t.h_x, t.h_p, t.h_t]), wheel_torque_matrix(params)


def _heading_jacobians(theta: Array, params: WIPMParams) -> tuple[Array, Array]:
    """Jacobians ``(Jv, Jw)`` (each ``3 bodies x 3 x 3``) of the body's CoM velocity and angular
    velocity and of each wheel's (left, right), in the heading frame, with respect to
    ``nu = [xd, psid, thetad]``. The constraints are built in: the axle midpoint moves at
    ``xd e_x`` (no side slip), each wheel rolls at ``phi_dot = (xd -+ sep/2 psid)/R`` about
    ``e_y``; the body turns at ``psid e_z + thetad e_y``. Depends on ``theta`` only."""
    R, sep = params.wheel_radius, params.wheel_separation
    L, cy = params.com_distance, params.com_lateral
    c, s = jnp.cos(theta), jnp.sin(theta)
    zero, one = jnp.zeros_like(c), jnp.ones_like(c)
    k = 0.5 * sep * one
    # body CoM r = Ry(theta) (0, cy, L) = (L s, cy, L c): v = xd e_x + (psid e_z + thd e_y) x r
    Jv_body = jnp.array([[one, -cy * one, L * c], [zero, L * s, zero], [zero, zero, -L * s]])
    Jw_body = jnp.array([[zero, zero, zero], [zero, zero, one], [zero, one, zero]])
    Jv_left = jnp.array([[one, -k, zero], [zero, zero, zero], [zero, zero, zero]])
    Jv_right = jnp.array([[one, k, zero], [zero, zero, zero], [zero, zero, zero]])
    Jw_left = jnp.array([[zero, zero, zero], [one / R, -k / R, zero], [zero, one, zero]])
    Jw_right = jnp.array([[zero, zero, zero], [one / R, k / R, zero], [zero, one, zero]])
    return jnp.stack([Jv_body, Jv_left, Jv_right]), jnp.stack([Jw_body, Jw_left, Jw_right])


def _heading_inertias(theta: Array, params: WIPMParams) -> tuple[Array, Array]:
    """Masses (3,) and heading-frame inertia tensors about each CoM (3 x 3 x 3) of the body and
    the two (axisymmetric) wheels."""
    M = params.body_mass
    com = jnp.stack([0.0 * M, params.com_lateral + 0.0 * M, params.com_distance + 0.0 * M])
    inertia_com_B = jnp.asarray(params.inertia_body) - M * (
        jnp.dot(com, com) * jnp.eye(3) - jnp.outer(com, com)
    )
    rot = rotation_y(theta)
    I_t, I_a = params.wheel_inertia_transverse, params.wheel_inertia
    wheel = jnp.diag(jnp.stack([I_t, I_a, I_t]))
    inertias = jnp.stack([rot @ inertia_com_B @ rot.T, wheel, wheel])
    masses = jnp.stack([M, params.wheel_mass, params.wheel_mass])
    return masses, inertias


def wheel_torque_matrix(params: WIPMParams) -> Array:
    """``B`` (3x2): the generalised forces on ``[x, psi, theta]`` of ``[tau_L, tau_R]``, the
    gradient of each wheel's relative rate ``phi_dot - thetad`` with respect to ``nu``:
    ``[(tau_L + tau_R)/R, sep/(2R) (tau_R - tau_L), -(tau_L + tau_R)]`` (docs/ERRATA.md §3)."""
    R, sep = params.wheel_radius, params.wheel_separation
    k = sep / (2.0 * R)
    one = jnp.ones_like(jnp.asarray(R))
    return jnp.stack([jnp.stack([1.0 / R, 1.0 / R]), jnp.stack([-k, k]), jnp.stack([-one, -one])])


def spatial_equations_kane(s: ArrayLike, params: WIPMParams) -> tuple[Array, Array, Array]:
    """The reference derivation of :func:`spatial_equations` by Kane's method (slow to compile
    and to run: kept to check the closed form against).

    Paper eq. ``dyn`` for the lumped three-body system (body, left and right wheel, each with
    the twist ``[v_i; w_i] = J_i nu``):

        A = sum_i m_i Jv_i^T Jv_i + Jw_i^T I_i Jw_i
        h = sum_i Jv_i^T (m_i a_i - F_gravity,i) + Jw_i^T (I_i al_i + w_i x I_i w_i) - Q_damping

    with ``a_i = Jdot_i nu`` and ``al_i`` the velocity-product parts of the accelerations. All
    vectors are in heading-frame components (the problem is invariant under ``x``, ``psi``,
    ``X0``, ``Y0``): the world-frame rate of a vector ``v`` is ``dv/dt|_heading + psid e_z x v``,
    and ``dv/dt|_heading = J nu_dot + (dJ/dtheta thetad) nu`` (the last term by ``jax.jvp``).
    The contact forces do no work under rolling without slip and drop out; gravity acts on the
    body CoM; each wheel joint's damping torque ``-d (phi_dot - thetad)`` acts on the wheel with
    its reaction on the body, i.e. through ``B`` like a motor torque (:func:`wheel_torque_matrix`).
    Returns ``(A, h, B)``.
    """
    s = jnp.asarray(s)
    theta, nu = s[2], s[3:6]
    psid, thd = s[4], s[5]
    (Jv, Jw), (dJv, dJw) = jax.jvp(
        lambda th: _heading_jacobians(th, params), (theta,), (jnp.ones_like(theta),)
    )
    v = Jv @ nu  # (3 bodies, 3)
    w = Jw @ nu
    turn = jnp.stack([0.0 * psid, 0.0 * psid, psid])  # heading frame's rate psid e_z

    def transport(vectors: Array) -> Array:  # psid e_z x v, for each body
        return jnp.cross(jnp.broadcast_to(turn, vectors.shape), vectors)

    a_bias = thd * (dJv @ nu) + transport(v)
    alpha_bias = thd * (dJw @ nu) + transport(w)
    masses, inertias = _heading_inertias(theta, params)
    g = params.gravity
    gravity = jnp.stack([0.0 * masses, 0.0 * masses, -g * masses], axis=1)  # (3 bodies, 3)
    inertia_w = jnp.einsum("bij,bj->bi", inertias, w)
    A = jnp.einsum("b,bij,bik->jk", masses, Jv, Jv) + jnp.einsum(
        "bij,bik,bkl->jl", Jw, inertias, Jw
    )
    h = jnp.einsum("bij,bi->j", Jv, masses[:, None] * a_bias - gravity) + jnp.einsum(
        "bij,bi->j",
        Jw,
        jnp.einsum("bij,bj->bi", inertias, alpha_bias) + jnp.cross(w, inertia_w),
    )
    B = wheel_torque_matrix(params)
    relative_rates = B.T @ nu  # [phi_L - thd, phi_R - thd]: B's columns are their gradients
    h = h + params.wheel_damping * (B @ relative_rates)
    return A, h, B


def _spatial_sdot(s: Array, xdd: Array, psidd: Array, thdd: Array) -> Array:
    xd, psid, thd, psi = s[3], s[4], s[5], s[1]
    return jnp.stack([xd, psid, thd, xdd, psidd, thdd, xd * jnp.cos(psi), xd * jnp.sin(psi)])


def spatial_torque_dynamics(s: ArrayLike, tau_wheels: ArrayLike, params: WIPMParams) -> Array:
    """3-D WIPM forward dynamics with the wheel torques ``[tau_L, tau_R]`` as input.

    ``s = [x, psi, theta, xd, psid, thetad, X0, Y0]``; returns
    ``[xd, psid, thetad, xdd, psidd, thdd, xd cos psi, xd sin psi]`` (solving the three rows of
    :func:`spatial_equations` by the adjugate of the symmetric ``A``).
    """
    s = jnp.asarray(s)
    tau = jnp.asarray(tau_wheels)
    t = spatial_terms(s, params)
    R = params.wheel_radius
    total = tau[0] + tau[1]
    b0 = total / R - t.h_x
    b1 = 0.5 * params.wheel_separation / R * (tau[1] - tau[0]) - t.h_p
    b2 = -total - t.h_t
    # cofactors of A = [[a_xx, a_xp, a_xt], [a_xp, a_pp, a_pt], [a_xt, a_pt, a_tt]]
    c00 = t.a_pp * t.a_tt - t.a_pt * t.a_pt
    c01 = t.a_xt * t.a_pt - t.a_xp * t.a_tt
    c02 = t.a_xp * t.a_pt - t.a_xt * t.a_pp
    c11 = t.a_xx * t.a_tt - t.a_xt * t.a_xt
    c12 = t.a_xp * t.a_xt - t.a_xx * t.a_pt
    c22 = t.a_xx * t.a_pp - t.a_xp * t.a_xp
    det = t.a_xx * c00 + t.a_xp * c01 + t.a_xt * c02
    xdd = (c00 * b0 + c01 * b1 + c02 * b2) / det
    psidd = (c01 * b0 + c11 * b1 + c12 * b2) / det
    thdd = (c02 * b0 + c12 * b1 + c22 * b2) / det
    return _spatial_sdot(s, xdd, psidd, thdd)


def _spatial_zero_dynamics(
    s: Array, u: Array, params: WIPMParams
) -> tuple[Array, Array, SpatialTerms]:
    """``(xdd, psidd, terms)`` for ``u = [thdd, tau_0]``: ``tau_1`` eliminated by
    ``R * (x row) + (theta row)``, the psi row kept with ``tau_0`` (docs/AUTHORS_CONFIG.md §2.3).
    The wheel damping cancels from the combined row (``R h_x + h_t``) as the torque does."""
    t = spatial_terms(s, params)
    R = params.wheel_radius
    thdd, tau_0 = u[0], u[1]
    r0 = R * t.a_xx + t.a_xt  # the combined row over [xdd, psidd, thdd]
    r1 = R * t.a_xp + t.a_pt
    r2 = R * t.a_xt + t.a_tt
    combined_h = R * t.h_x + t.h_t
    e0 = -r2 * thdd - combined_h
    e1 = tau_0 - t.a_pt * thdd - t.h_p
    det = r0 * t.a_pp - r1 * t.a_xp
    xdd = (t.a_pp * e0 - r1 * e1) / det
    psidd = (r0 * e1 - t.a_xp * e0) / det
    return xdd, psidd, t


def spatial_dynamics(s: ArrayLike, u: ArrayLike, params: WIPMParams) -> Array:
    """3-D WIPM with ``u = [thdd, tau_0]`` (the MPC's model; docs/AUTHORS_CONFIG.md §2.1-2.3
    structure).

    ``tau_0 = sep/(2R) (tau_R - tau_L)`` is the generalised force on ``psi`` (docs/ERRATA.md §3).
    The pitch torque ``tau_1`` is eliminated by ``R * (x row) + (theta row)`` and the 2x2 system for
    ``(xdd, psidd)`` is solved. Returns ``[xd, psid, thetad, xdd, psidd, thdd, xd cos psi,
    xd sin psi]``.
    """
    s = jnp.asarray(s)
    u = jnp.asarray(u)
    xdd, psidd, _ = _spatial_zero_dynamics(s, u, params)
    return _spatial_sdot(s, xdd, psidd, u[0])


def inverse_dynamics(s: ArrayLike, u: ArrayLike, params: WIPMParams) -> tuple[Array, Array]:
    """The wheel torques ``(tau_L, tau_R)`` that realise ``u = [thdd, tau_0]`` at state ``s``.

    ``tau_1`` from the theta row with the accelerations of :func:`spatial_dynamics`
    (docs/AUTHORS_CONFIG.md §2.4), then the inverse map of wip_gym.wheel_torques:
    ``tau_L = (-tau_1 - 2R/sep tau_0) / 2``, ``tau_R = (-tau_1 + 2R/sep tau_0) / 2``.
    """
    s = jnp.asarray(s)
    u = jnp.asarray(u)
    xdd, psidd, t = _spatial_zero_dynamics(s, u, params)
    tau_1 = t.a_xt * xdd + t.a_pt * psidd + t.a_tt * u[0] + t.h_t
    difference = 2.0 * params.wheel_radius / params.wheel_separation * u[1]  # tau_R - tau_L
    return 0.5 * (-tau_1 - difference), 0.5 * (-tau_1 + difference)


# ------------------------------------------------------------------------- linearisation
def linearize(
    dynamics: Dynamics, s: ArrayLike, u: ArrayLike, params: WIPMParams
) -> tuple[Array, Array]:
    """Continuous-time Jacobians ``(A, B) = (d f/d s, d f/d u)`` of ``dynamics`` at ``(s, u)``
    by ``jax.jacfwd``; ``B`` has shape ``(n_s, n_u)`` (``n_u = 1`` for a scalar control).
    Jit it with ``jax.jit(linearize, static_argnums=0)``."""
    s = jnp.asarray(s, dtype=jnp.float64)
    u = jnp.asarray(u, dtype=jnp.float64)
    A = jax.jacfwd(dynamics, argnums=0)(s, u, params)
    B = jax.jacfwd(dynamics, argnums=1)(s, u, params)
    return A, jnp.reshape(B, (s.shape[0], -1))


def discretize(dynamics: Dynamics, dt: float) -> Dynamics:
    """The paper's explicit-Euler discretisation: ``f(s, u, params) = s + dt dynamics(s, u,
    params)`` (docs/AUTHORS_CONFIG.md §3.1)."""

    def step(s: ArrayLike, u: ArrayLike, params: WIPMParams) -> Array:
        s = jnp.asarray(s)
        return s + dt * dynamics(s, u, params)

    return step
