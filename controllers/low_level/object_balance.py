"""The balance of an object resting on the tray, as linear rows in the accelerations ``nu_dot``.

An unattached object (the cup) stays on the tray while the contact wrench its motion needs lies
in what the support can give: a force inside the friction cone, with a positive normal part,
and a zero-moment point inside the support polygon. At a given state that wrench is affine in
the robot's accelerations, so these conditions are linear inequalities of the task QP (Heins and
Schoellig, "Keep It Upright", RA-L 2023, in the zero-moment-point form of their earlier code;
docs/upright.md §2 derives the rows and says how they are tested against MuJoCo).

Frames and quantities, per unit of the object's weight ``m g`` (so that the rows do not depend on
its mass):

* the tray frame ``R`` (world from tray, its ``z`` the plate's normal) of a site on the plate's
  top (``tray_top``), ``s`` that site's position, ``c = s + R o`` the object's centre of mass,
  ``o = (o_x, o_y, h)`` its place on the plate and its height above it;
* ``a_c = J_c nu_dot + d_c`` the centre of mass's acceleration (``J_c = J_s - [R o]x J_r``, ``d_c``
  the drift ``Jdot nu`` of the same point) and ``alpha = J_r nu_dot + d_r`` the tray's angular
  acceleration, both in world (MuJoCo's point Jacobians mapped to the minimal coordinates by
  ``J_tf``; drifts from :class:`controllers.low_level.motion_probe.MotionProbe`);
* the contact force the plate must give, in the tray frame: ``f = R^T (a_c - g_vec) / g``; its
  moment about the centre of mass: ``tau = (R^T I R alpha + omega x I omega) / (m g)`` with ``I``
  the object's inertia about its centre of mass in tray axes (a cylinder's by default);
* its zero-moment point on the plate, relative to the point under the centre of mass:
  ``p = (-(h f_x + tau_y), tau_x - h f_y) / f_z``.

The rows (each ``G nu_dot + b <= 0``):

* friction, the inner pyramid of the planning coefficient ``mu' = (1 - margin) mu``:
  ``+-f_x +- f_y - mu' f_z <= 0`` (exact along the tray's axes, conservative by at most
  ``sqrt(2)`` between them);
* contact: ``n_min - f_z <= 0`` (the object keeps at least that fraction of its weight on the
  plate);
* tipping: ``p`` inside the support polygon, one row per edge.

:meth:`ObjectBalance.tangential` gives the rows of ``(f_x, f_y)`` at the plate's point (the
object's place, not its centre of mass): the tangential specific force the tray's motion puts
on the object, which the upright controller drives to zero as a task (docs/upright.md §3 says
why the task leaves out the tray's angular acceleration).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import mujoco
import numpy as np
from numpy.typing import NDArray

from wip_gym.robot_model import RobotModel
from wip_gym.scene import CUP_FOOT_RADIUS, CUP_HALF_HEIGHT, CUP_RADIUS, GRAVITY

Array = NDArray[np.float64]


def _cup_support() -> tuple[tuple[float, float], ...]:
    """The cup's support polygon in its own frame: the four foot spheres it stands on
    (wip_gym/scene.py ``add_cup``), at radius ``CUP_RADIUS - CUP_FOOT_RADIUS`` on its axes."""
    r = CUP_RADIUS - CUP_FOOT_RADIUS
    return ((r, 0.0), (0.0, r), (-r, 0.0), (0.0, -r))


def cylinder_inertia_per_mass(radius: float, height: float) -> tuple[float, float, float]:
    """Principal moments of inertia per unit mass of a solid cylinder about its centre of
    mass, axis along ``z``: ``((3 r^2 + h^2) / 12, (3 r^2 + h^2) / 12, r^2 / 2)``."""
    side = (3.0 * radius * radius + height * height) / 12.0
    return (side, side, 0.5 * radius * radius)


@dataclass(frozen=True)
class CarriedObject:
    """What a controller is told about an object resting on the tray (defaults: the cup of
    the tray tasks, wip_gym/scene.py).

    Attributes:
        friction: the object-tray friction coefficient it plans with; None: the scenario's
            declared ``cup_friction`` (the env argument), as a waiter is told the cup is
            slippery. Set it apart from the true value to study model error.
        margin: planned with ``(1 - margin) friction`` (Heins and Schoellig plan with 10 %
            less; 0.2 here: the commanded and the realised accelerations differ by up to 6 %
            of the tangential force with the nominal model, docs/upright.md §2).
        com_height: the centre of mass above the support plane (m); the cup's half height.
        place: the object's place on the plate in the tray frame (m).
        support: the support polygon's vertices (m, counter-clockwise, in the tray's axes,
            relative to the point under the centre of mass): the cup's four feet.
        inertia_per_mass: principal moments of inertia per unit mass about the centre of mass
            in the tray's axes (m^2): the cup's solid cylinder.
        min_normal: the fraction of its weight the object keeps on the plate (no lift-off).
    """

    friction: float | None = None
    margin: float = 0.2
    com_height: float = CUP_HALF_HEIGHT
    place: tuple[float, float] = (0.0, 0.0)
    support: tuple[tuple[float, float], ...] = field(default_factory=_cup_support)
    inertia_per_mass: tuple[float, float, float] = cylinder_inertia_per_mass(
        CUP_RADIUS, 2.0 * CUP_HALF_HEIGHT
    )
    min_normal: float = 0.1

    def __post_init__(self) -> None:
        if self.friction is not None and not (np.isfinite(self.friction) and self.friction > 0):
            raise ValueError(f"friction must be positive (or None), got {self.friction!r}")
        if not 0.0 <= self.margin < 1.0:
            raise ValueError(f"margin must be in [0, 1), got {self.margin!r}")
        if not (np.isfinite(self.com_height) and self.com_height > 0):
            raise ValueError(f"com_height must be positive, got {self.com_height!r}")
        if not 0.0 <= self.min_normal < 1.0:
            raise ValueError(f"min_normal must be in [0, 1), got {self.min_normal!r}")
        vertices = np.asarray(self.support, dtype=float)
        if vertices.ndim != 2 or vertices.shape[1] != 2 or len(vertices) < 3:
            raise ValueError(f"support must hold 3 or more (x, y) vertices, got {self.support!r}")
        if not all(v > 0 for v in self.inertia_per_mass):
            raise ValueError(f"inertia_per_mass must be positive, got {self.inertia_per_mass!r}")
        # the polygon must hold the point under the centre of mass (the origin), in
        # counter-clockwise order: each edge's inward normal then has the origin on its side
        for offset, _ in _edges(vertices):
            if offset > 0.0:
                raise ValueError(
                    "support must be a convex polygon around (0, 0) listed counter-clockwise, "
                    f"got {self.support!r}"
                )


def _edges(vertices: Array) -> list[tuple[float, Array]]:
    """Per edge of the polygon: ``(n . v, n)`` with ``n`` the inward unit normal of the edge
    from vertex ``v``, so that a point ``p`` is inside when ``n . p >= n . v`` for every edge."""
    out = []
    for i, v in enumerate(vertices):
        w = vertices[(i + 1) % len(vertices)]
        edge = w - v
        normal = np.array([-edge[1], edge[0]]) / np.linalg.norm(edge)  # left of the edge
        out.append((float(normal @ v), normal))
    return out


def _cross(a: Array, b: Array) -> Array:
    """``a x b`` of two 3-vectors (``np.cross`` costs 20 us per call at this size)."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


class TrayMotion(NamedTuple):
    """The tray's frame and motion at one state (world): ``R`` (world from tray), the plate
    site's linear and angular Jacobians over ``nu`` (``J_s``, ``J_r``), its drift acceleration
    ``a_s``, the angular velocity ``omega`` and angular drift ``omega_drift``."""

    R: Array
    J_s: Array
    a_s: Array
    J_r: Array
    omega: Array
    omega_drift: Array


def _skew(v: Array) -> Array:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


class ObjectBalance:
    """The balance rows of one object on the tray whose plate's top is site ``site`` of the
    robot's model (module docstring). Rows are made for the robot's current state: the
    Jacobians from ``robot.data`` (after ``robot.update``), the drifts from a motion probe
    updated at the same state."""

    def __init__(self, robot: RobotModel, site: int, carried: CarriedObject, friction: float):
        if not 0 <= site < robot.model.nsite:
            raise ValueError(f"site {site} is not a site of the model (nsite {robot.model.nsite})")
        if not (np.isfinite(friction) and friction > 0):
            raise ValueError(f"friction must be positive, got {friction!r}")
        self.site = site
        self.carried = carried
        self.friction = friction
        self.planning_friction = (1.0 - carried.margin) * friction
        self._inertia = np.diag(carried.inertia_per_mass)
        self._edges = _edges(np.asarray(carried.support, dtype=float))
        self._jp = np.zeros((3, robot.model.nv))
        self._jr = np.zeros((3, robot.model.nv))
        mu = self.planning_friction
        # the friction faces and the contact row as linear maps of (f, tau)
        rows = [[sx, sy, -mu, 0.0, 0.0, 0.0] for sx in (1.0, -1.0) for sy in (1.0, -1.0)]
        rows.append([0.0, 0.0, -1.0, 0.0, 0.0, 0.0])
        h = carried.com_height
        for offset, n in self._edges:
            # offset f_z + n_x (h f_x + tau_y) - n_y (tau_x - h f_y) <= 0
            rows.append([n[0] * h, n[1] * h, offset, -n[1], n[0], 0.0])
        self._wrench_rows = np.array(rows)
        self._constants = np.zeros(len(rows))
        self._constants[4] = carried.min_normal
        #: names of the rows, in order
        self.row_names = (
            *(f"friction{i}" for i in range(4)),
            "contact",
            *(f"tipping{i}" for i in range(len(self._edges))),
        )

    @property
    def rows_count(self) -> int:
        return len(self._constants)

    @property
    def wrench_rows(self) -> Array:
        """The rows as linear maps of the wrench ``(f, tau)`` (rows x 6): ``G = rows W``."""
        return self._wrench_rows

    @property
    def constants(self) -> Array:
        """The rows' constant terms: ``b = rows w + constants``."""
        return self._constants

    def tray_motion(self, robot: RobotModel, probe: object | None) -> TrayMotion:
        """The tray's motion at the robot's state, which every row reads (compute it once per
        step and hand it to :meth:`rows` and :meth:`tangential`). ``probe`` None: the drifts
        and ``omega`` zero (the rows' Jacobians are right, their constant parts are not)."""
        m, d = robot.model, robot.data
        mujoco.mj_jacSite(m, d, self._jp, self._jr, self.site)
        J_tf = robot.J_tf
        if probe is None:
            a_s = omega = omega_drift = (0.0, 0.0, 0.0)
        else:
            _, _, a_s, omega, omega_drift = probe.site_motion(self.site)  # type: ignore[attr-defined]
        return TrayMotion(
            d.site_xmat[self.site].reshape(3, 3).copy(),
            self._jp @ J_tf,
            np.array(a_s),
            self._jr @ J_tf,
            np.array(omega),
            np.array(omega_drift),
        )

    @staticmethod
    def _point(motion: TrayMotion, lever: Array) -> tuple[Array, Array]:
        """``(J_p, d_p)`` of the point ``lever`` (tray frame) from the plate's site, on the
        tray: its linear Jacobian over ``nu`` and its drift acceleration (world)."""
        r = motion.R @ lever
        omega, drift = motion.omega, motion.omega_drift
        J_p = motion.J_s - _skew(r) @ motion.J_r
        return J_p, motion.a_s + _cross(drift, r) + _cross(omega, _cross(omega, r))

    def wrench(
        self, robot: RobotModel, probe: object | None, motion: TrayMotion | None = None
    ) -> tuple[Array, Array]:
        """``(W, w)`` with the contact wrench ``(f, tau) = W nu_dot + w`` (tray frame, per unit
        weight; module docstring): what the plate must give the object for it to move with the
        tray. ``probe`` is a motion probe updated at the robot's state; ``motion`` the tray's
        (:meth:`tray_motion`, computed here when None)."""
        motion = motion or self.tray_motion(robot, probe)
        x, y = self.carried.place
        J_c, d_c = self._point(motion, np.array([x, y, self.carried.com_height]))
        Rt, J_r, omega, omega_drift = motion.R.T, motion.J_r, motion.omega, motion.omega_drift
        W = np.empty((6, J_c.shape[1]))
        w = np.empty(6)
        W[:3] = Rt @ J_c / GRAVITY
        w[:3] = Rt @ (d_c - np.array([0.0, 0.0, -GRAVITY])) / GRAVITY
        inertia = self._inertia
        omega_t = Rt @ omega
        W[3:] = inertia @ Rt @ J_r / GRAVITY
        w[3:] = (inertia @ Rt @ omega_drift + _cross(omega_t, inertia @ omega_t)) / GRAVITY
        return W, w

    def rows(
        self, robot: RobotModel, probe: object | None, motion: TrayMotion | None = None
    ) -> tuple[Array, Array]:
        """``(G, b)``: the balance conditions as ``G nu_dot + b <= 0`` (friction, contact,
        tipping; :attr:`row_names`)."""
        W, w = self.wrench(robot, probe, motion)
        return self._wrench_rows @ W, self._wrench_rows @ w + self._constants

    def tangential(
        self, robot: RobotModel, probe: object | None, motion: TrayMotion | None = None
    ) -> tuple[Array, Array]:
        """``(T, t)``: the tangential specific force at the object's place on the plate,
        ``(f_x, f_y) = T nu_dot + t`` (tray frame, in g), without the tray's angular
        acceleration's share at the centre of mass (docs/upright.md §3)."""
        motion = motion or self.tray_motion(robot, probe)
        x, y = self.carried.place
        J_p, d_p = self._point(motion, np.array([x, y, 0.0]))
        Rt = motion.R.T[:2]
        return Rt @ J_p / GRAVITY, Rt @ (d_p - np.array([0.0, 0.0, -GRAVITY])) / GRAVITY
