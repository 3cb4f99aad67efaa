"""Two hands that hold one free tray, held as one rigid support (docs/upright.md §6).

A free tray resting on two grippers (Krang's finger plates) stays put only while the grippers
keep their places relative to each other: if one moves against the other, the plates slide
under the tray (its contacts then pull it at their friction limit) and it leaves them. Each
hand's own tasks are soft, and the upright controller weights its tray's tangential force far
above them, so nothing in the task QP held the two hands' relative pose.

:class:`HandPair` gives that as rows of the task QP's cost: the pose of hand ``b`` relative to
hand ``a``, held at its value at reset. With ``P = p_a + R_a r_0`` the point of hand ``a``'s
body where hand ``b`` sat at reset (``r_0 = R_a^T (p_b - p_a)`` then), and the rotation error
``e_R = rotation_error(R_b, R_a R_ab0)`` (``controllers.low_level.tasks.rotation_error``, world):

    (J_b - J_P) nu_dot + (d_b - d_P) = -kp (p_b - P) - kv (v_b - v_P)
    (Jr_b - Jr_a) nu_dot + (dw_b - dw_a) = -kp e_R - kv (w_b - w_a)

in world, each side weighted; ``J`` are MuJoCo's point Jacobians mapped to the minimal
coordinates by ``J_tf`` and ``d`` the drifts ``Jdot nu`` (``MotionProbe.site_motion``, ``P``'s
by the rigid-body lever from hand ``a``'s site, :meth:`HandPair.drift`). The
rows hold only the hands' relative motion: both may move together as one body (the tray's tilt
and place are the other tasks' business). Tested against central differences of MuJoCo's
kinematics (tests/test_hand_pair.py). Its compiled rows (``compiled_tasks.hand_pair_rows``, kind
``HAND_PAIR``: hand ``a`` the item's site, hand ``b`` its paired site) let the task QP take its
one-call step with the pair; tests/test_hand_pair.py holds them to these.
"""

from __future__ import annotations

from typing import ClassVar

import mujoco
import numpy as np
from numpy.typing import NDArray

from controllers.low_level import compiled_tasks as ct
from controllers.low_level.tasks import rotation_error
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]


class HandPair:
    """The relative pose of site ``b`` in site ``a``'s frame, held at its value at
    construction (the robot's current state), as weighted cost rows (module docstring).
    ``site`` and ``paired_site`` (hands ``a`` and ``b``) are the compiled stack's two site
    slots."""

    compiled_kind: ClassVar[int | None] = ct.HAND_PAIR

    def __init__(
        self,
        robot: RobotModel,
        site_a: int,
        site_b: int,
        weight: float,
        kp: float,
        kv: float,
    ) -> None:
        m = robot.model
        for site in (site_a, site_b):
            if not 0 <= site < m.nsite:
                raise ValueError(f"site {site} is not a site of the model (nsite {m.nsite})")
        if site_a == site_b:
            raise ValueError(f"two different sites, got {site_a} twice")
        for name, value in (("weight", weight), ("kp", kp), ("kv", kv)):
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
        self.robot, self.site_a, self.site_b = robot, site_a, site_b
        self.name = "hand_pair"
        self.weight, self.kp, self.kv = float(weight), float(kp), float(kv)
        self._body_a = int(m.site_bodyid[site_a])
        self._body_b = int(m.site_bodyid[site_b])
        d = robot.data
        R_a = d.site_xmat[site_a].reshape(3, 3)
        #: hand b's place and rotation in hand a's frame at reset
        self.offset = R_a.T @ (d.site_xpos[site_b] - d.site_xpos[site_a])
        self.rotation = R_a.T @ d.site_xmat[site_b].reshape(3, 3)
        self._jac = np.zeros((6, m.nv))

    @property
    def site(self) -> int:
        """Hand ``a``'s site: the compiled stack's site slot of this item."""
        return self.site_a

    @property
    def paired_site(self) -> int:
        """Hand ``b``'s site: the compiled stack's second site slot of this item."""
        return self.site_b

    def errors(self, robot: RobotModel) -> tuple[Array, Array]:
        """``(p_b - P, e_R)`` (world): hand b's position and rotation errors from where hand
        a's frame carries its reset pose."""
        d = robot.data
        R_a = d.site_xmat[self.site_a].reshape(3, 3)
        point = d.site_xpos[self.site_a] + R_a @ self.offset
        R_b = d.site_xmat[self.site_b].reshape(3, 3)
        return d.site_xpos[self.site_b] - point, rotation_error(R_b, R_a @ self.rotation)

    def jacobian(self, robot: RobotModel) -> Array:
        """``(6, n_min)``: the relative velocity ``(v_b - v_P, w_b - w_a)`` over ``nu``."""
        m, d, jac = robot.model, robot.data, self._jac
        R_a = d.site_xmat[self.site_a].reshape(3, 3)
        point = d.site_xpos[self.site_a] + R_a @ self.offset
        mujoco.mj_jac(m, d, jac[:3], jac[3:], d.site_xpos[self.site_b], self._body_b)
        J_b = jac @ robot.J_tf
        mujoco.mj_jac(m, d, jac[:3], jac[3:], point, self._body_a)
        return J_b - jac @ robot.J_tf

    def drift(self, robot: RobotModel, probe: object) -> Array:
        """``(6,)``: the relative drift acceleration ``Jdot nu`` (world), from a motion probe
        updated at the robot's state: each site's motion at the probe's state
        (``MotionProbe.site_motion``), ``P``'s drift that of hand ``a``'s body at the lever
        ``r = R_a offset``, ``a_a + omega_drift x r + omega x (omega x r)`` (as
        ``ObjectBalance``'s points on the tray)."""
        R_a = robot.data.site_xmat[self.site_a].reshape(3, 3)
        r = R_a @ self.offset
        _, _, a_b, _, dw_b = probe.site_motion(self.site_b)  # type: ignore[attr-defined]
        _, _, a_a, w_a, dw_a = probe.site_motion(self.site_a)  # type: ignore[attr-defined]
        omega, spin = np.array(w_a), np.array(dw_a)
        a_p = np.array(a_a) + np.cross(spin, r) + np.cross(omega, np.cross(omega, r))
        return np.array([*a_b, *dw_b]) - np.concatenate([a_p, spin])

    # the task QP's task protocol (controllers.low_level.task_qp)
    def reference_acceleration(self, robot: RobotModel) -> Array:
        """``-kp (p_b - P, e_R) - kv (relative velocity)``: the relative acceleration wanted."""
        position, rotation = self.errors(robot)
        rate = self.jacobian(robot) @ robot.nu
        return -self.kp * np.concatenate([position, rotation]) - self.kv * rate

    def weights(self) -> Array:
        return np.full(6, self.weight)

    def jdot_nu(self, probe: object) -> Array:
        """The relative drift at the state of the robot this pair was made for."""
        return self.drift(self.robot, probe)

    def parameters(self) -> list[float]:
        """``(kp, kv, weight, offset (3), rotation (3 x 3, row-major))``: what the compiled rows
        read every step."""
        return [
            self.kp,
            self.kv,
            self.weight,
            *self.offset.tolist(),
            *self.rotation.ravel().tolist(),
        ]

    def rows(self, robot: RobotModel, probe: object) -> tuple[Array, Array]:
        """``(A, a)``: the weighted cost rows ``||A nu_dot + a||^2`` (module docstring), the
        task's rows as the task QP weighs them."""
        J = self.jacobian(robot)
        wanted = self.reference_acceleration(robot)
        return self.weight * J, self.weight * (self.drift(robot, probe) - wanted)
