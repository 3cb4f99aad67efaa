"""The wheeled inverted pendulum model (WIPM): the paper's simplified model, in JAX.

The whole robot lumped into one rigid body (mass ``M``, CoM at distance ``L`` from the axle) on
two wheels, with the parameters ``lambda(q)`` of the current pose (paper section "Simplified
Model"; :func:`params_from_lambda`). Pure, jit-friendly functions in the style of trajax:
``dynamics(s, u, params) -> sdot`` in continuous time, with :func:`discretize` for the paper's
explicit-Euler steps and :func:`linearize` for the Jacobians.

Planar model (state ``s = [theta, thetad, x, xd]``), ERRATA 1. The two rows of the one-link WIP,
with ``m_w``, ``I_w`` the mass and axial inertia of BOTH wheels, ``I`` the body's pitch inertia
about the axle, ``tau_w = tau_L + tau_R`` the total wheel torque and ``d`` one wheel joint's
viscous damping (acting on the wheel's rotation relative to the body, ``xd / R - thd``):

    x row:  (m_w + I_w/R^2 + M) xdd + M L cos th thdd - M L sin th thd^2
                = tau_w / R - 2 d (xd/R - thd) / R
    th row: M L cos th xdd + I thdd - M g L sin th = -tau_w + 2 d (xd/R - thd)

``R * (x row) + (th row)`` eliminates the torque (and the damping with it) and gives the zero
dynamics, paper eqs. ``WIPzero`` / ``WIPdyn`` as corrected by ERRATA 1:

    (alpha + cos th) xdd + (beta + R cos th) thdd = g sin th + R sin th thd^2
    alpha = R (M + m_w + I_w/R^2) / (M L),   beta = I / (M L)

The paper's printed form (``beta + cos th`` and ``- R sin th thd^2``) is kept in
:func:`paper_printed_planar_dynamics` only so that a test can show it is wrong.

3-D model (state ``s = [x, psi, theta, xd, psid, thetad, X0, Y0]``), the structure of the
authors' Krang3D model (reference/krang_facts.md 2.1-2.4) but derived here exactly, by Kane's
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
``tau_0 = sep/(2R) (tau_R - tau_L)`` the generalised force on ``psi`` (ERRATA 3;
wip_gym.wheel_torques) and ``tau_1 = -(tau_L + tau_R)`` the torque on the body pitch (paper
eq. ``dyn``, ``simple1``/``simple2`` for the lumped model).

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

jax.config.update("jax_enable_x64", True)

if TYPE_CHECKING:
    from wip_gym.robot_model import WIPMParameters

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
        wheel_separation: distance between the wheels (the paper's other ``L``, ERRATA 2) (m).
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
    rot = np.asarray(rotation_y(theta))
    inertia_body = rot.T @ np.asarray(p.inertia_axle, dtype=float) @ rot
    inertia_body = 0.5 * (inertia_body + inertia_body.T)

    def f(value: float) -> Array:
        return jnp.asarray(float(value), dtype=jnp.float64)

    return WIPMParams(
        body_mass=f(p.body_mass),
        com_distance=f(p.com_distance),
        com_lateral=f(p.com[1]),
        inertia_body=jnp.asarray(inertia_body, dtype=jnp.float64),
        wheel_mass=f(p.wheel_mass),
        wheel_inertia=f(p.wheel_inertia),
        wheel_inertia_transverse=f(p.wheel_inertia_transverse),
        wheel_damping=f(p.wheel_damping),
        wheel_radius=f(p.wheel_radius),
        wheel_separation=f(p.wheel_separation),
        gravity=f(p.gravity),
    )


def _solve2(A: Array, b: Array) -> Array:
    """``A^-1 b`` for a 2x2 ``A`` by Cramer's rule (small, well-conditioned systems; much
    cheaper to compile than a pivoted LU solve)."""
    det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
    return jnp.stack([A[1, 1] * b[0] - A[0, 1] * b[1], A[0, 0] * b[1] - A[1, 0] * b[0]]) / det


def _solve3(A: Array, b: Array) -> Array:
    """``A^-1 b`` for a 3x3 ``A`` by its adjugate: the columns of ``A^-1 det(A)`` are
    ``r1 x r2, r2 x r0, r0 x r1`` for the rows ``r0, r1, r2`` of ``A``."""
    c0, c1, c2 = jnp.cross(A[1], A[2]), jnp.cross(A[2], A[0]), jnp.cross(A[0], A[1])
    return (b[0] * c0 + b[1] * c1 + b[2] * c2) / jnp.dot(A[0], c0)


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
    ``f_c`` from eq. ``WIPzero``, corrected per ERRATA 1).

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


def paper_printed_planar_dynamics(s: ArrayLike, u: ArrayLike, params: WIPMParams) -> Array:
    """The paper's eq. ``WIPdyn`` AS PRINTED (wrong; ERRATA 1), kept only for a test.

    ``xdd = (g sin th - R sin th thd^2 - (beta + cos th) u) / (alpha + cos th)`` with the printed
    ``alpha = R/(M L) (M + m_w + I_w/R^2)`` and ``beta = I/(M L)`` (``m_w``, ``I_w`` of both
    wheels). Same state and control as :func:`planar_dynamics`.
    """
    s = jnp.asarray(s)
    thdd = jnp.reshape(jnp.asarray(u), (-1,))[0]
    th, thd, xd = s[0], s[1], s[3]
    R, g = params.wheel_radius, params.gravity
    alpha, beta = _planar_alpha_beta(params)
    c, sn = jnp.cos(th), jnp.sin(th)
    xdd = (g * sn - R * sn * thd**2 - (beta + c) * thdd) / (alpha + c)
    return jnp.stack([thd, thdd, xd, xdd])


def _planar_rows(s: Array, params: WIPMParams) -> tuple[Array, Array, Array]:
    """Mass matrix ``A`` (rows x, th over ``[xdd, thdd]``), the right-hand side without the
    torque, and the torque column ``b``: ``A [xdd, thdd] = rhs + b tau_w`` (ERRATA 1)."""
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
    rows of ERRATA 1 before the torque is eliminated, with the wheels' viscous damping).

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
    ``[(tau_L + tau_R)/R, sep/(2R) (tau_R - tau_L), -(tau_L + tau_R)]`` (ERRATA 3)."""
    R, sep = params.wheel_radius, params.wheel_separation
    k = sep / (2.0 * R)
    one = jnp.ones_like(jnp.asarray(R))
    return jnp.stack([jnp.stack([1.0 / R, 1.0 / R]), jnp.stack([-k, k]), jnp.stack([-one, -one])])


def spatial_equations(s: ArrayLike, params: WIPMParams) -> tuple[Array, Array, Array]:
    """The 3-D WIPM's equations ``A nu_dot + h = B [tau_L, tau_R]`` over
    ``nu = [xd, psid, thetad]`` at state ``s = [x, psi, theta, xd, psid, thetad, X0, Y0]``.

    Kane's method (paper eq. ``dyn`` for the lumped three-body system: body, left and right
    wheel, each with the twist ``[v_i; w_i] = J_i nu``):

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


def _spatial_sdot(s: Array, nu_dot: Array) -> Array:
    xd, psid, thd, psi = s[3], s[4], s[5], s[1]
    return jnp.stack(
        [xd, psid, thd, nu_dot[0], nu_dot[1], nu_dot[2], xd * jnp.cos(psi), xd * jnp.sin(psi)]
    )


def spatial_torque_dynamics(s: ArrayLike, tau_wheels: ArrayLike, params: WIPMParams) -> Array:
    """3-D WIPM forward dynamics with the wheel torques ``[tau_L, tau_R]`` as input.

    ``s = [x, psi, theta, xd, psid, thetad, X0, Y0]``; returns
    ``[xd, psid, thetad, xdd, psidd, thdd, xd cos psi, xd sin psi]`` (solving the three rows of
    :func:`spatial_equations`).
    """
    s = jnp.asarray(s)
    A, h, B = spatial_equations(s, params)
    nu_dot = _solve3(A, B @ jnp.asarray(tau_wheels) - h)
    return _spatial_sdot(s, nu_dot)


def _spatial_zero_dynamics(s: Array, u: Array, params: WIPMParams) -> tuple[Array, Array, Array]:
    """``(nu_dot, A, h)`` for ``u = [thdd, tau_0]``: ``tau_1`` eliminated by
    ``R * (x row) + (theta row)``, the psi row kept with ``tau_0`` (krang_facts 2.3)."""
    A, h, _ = spatial_equations(s, params)
    R = params.wheel_radius
    thdd, tau_0 = u[0], u[1]
    row = R * A[0] + A[2]
    lhs = jnp.array([[row[0], row[1]], [A[1, 0], A[1, 1]]])
    rhs = jnp.stack([-row[2] * thdd - (R * h[0] + h[2]), tau_0 - A[1, 2] * thdd - h[1]])
    xdd, psidd = _solve2(lhs, rhs)
    return jnp.stack([xdd, psidd, thdd]), A, h


def spatial_dynamics(s: ArrayLike, u: ArrayLike, params: WIPMParams) -> Array:
    """3-D WIPM with ``u = [thdd, tau_0]`` (the MPC's model; krang_facts 2.1-2.3 structure).

    ``tau_0 = sep/(2R) (tau_R - tau_L)`` is the generalised force on ``psi`` (ERRATA 3). The pitch
    torque ``tau_1`` is eliminated by ``R * (x row) + (theta row)`` and the 2x2 system for
    ``(xdd, psidd)`` is solved. Returns ``[xd, psid, thetad, xdd, psidd, thdd, xd cos psi,
    xd sin psi]``.
    """
    s = jnp.asarray(s)
    nu_dot, _, _ = _spatial_zero_dynamics(s, jnp.asarray(u), params)
    return _spatial_sdot(s, nu_dot)


def inverse_dynamics(s: ArrayLike, u: ArrayLike, params: WIPMParams) -> tuple[Array, Array]:
    """The wheel torques ``(tau_L, tau_R)`` that realise ``u = [thdd, tau_0]`` at state ``s``.

    ``tau_1`` from the theta row with the accelerations of :func:`spatial_dynamics`
    (krang_facts 2.4), then the inverse map of wip_gym.wheel_torques:
    ``tau_L = (-tau_1 - 2R/sep tau_0) / 2``, ``tau_R = (-tau_1 + 2R/sep tau_0) / 2``.
    """
    s = jnp.asarray(s)
    u = jnp.asarray(u)
    nu_dot, A, h = _spatial_zero_dynamics(s, u, params)
    tau_1 = A[2] @ nu_dot + h[2]
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
    params)`` (krang_facts 3.1)."""

    def step(s: ArrayLike, u: ArrayLike, params: WIPMParams) -> Array:
        s = jnp.asarray(s)
        return s + dt * dynamics(s, u, params)

    return step
