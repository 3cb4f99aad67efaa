"""Velocities and drift accelerations of task points at the robot's idealised state (issue 6).

Each task row of the QP needs ``Jdot nu``: the time derivative of ``J(q) nu`` along the motion
at fixed ``nu`` (paper section "Optimization Based Control": ``xdd = J nu_dot + Jdot nu``). It
was a central finite difference of ``J nu`` between two states ``(q +- eps nu, nu)`` placed on
the floor by ``RobotModel.full_state``. Here it is exact: one MuJoCo state, the same idealised
``full_state(q, nu)`` (wheels on the floor, axle level: the states the finite difference
probed), its kinematics and ``mj_comVel``, and with ``nu_dot = 0``

    qacc_0 = Jdot_tf nu,    a_point = jac qacc_0 + jacDot qvel    (MuJoCo's ``mj_jacDot``)

for a point on a body (the angular part likewise), and for the body's CoM (wheels excluded)
``sum m_i a_i`` from ``mj_rnePostConstraint``'s ``cfrc_int`` (the linear part of a subtree's
net force is ``sum m_i (a_i - g)``, whatever the reference point). The tasks
(``controllers.tasks``) turn these world quantities into axle-frame drifts.

Why the idealised state and not the robot's own: the measured state leaves the manifold by
~1e-5 rad and ~2e-3 m/s (contact compliance: roll, vertical speed), which the minimal model
ignores; the finite difference never saw them, and neither does this.
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]


class MotionProbe:
    """World velocities and drift accelerations (``nu_dot = 0``) at ``full_state(q, nu)``.

    Call :meth:`update` once per control step after ``robot.update``; then
    :meth:`point_motion`, :meth:`angular_motion` and :meth:`com_motion` read it (memoised).
    """

    def __init__(self, robot: RobotModel) -> None:
        m = robot.model
        self.model = m
        self.data = mujoco.MjData(m)
        lay = robot.layout
        self._nq, self._nv = lay.nq, lay.nv
        self._base = lay.base_body
        self._wheels = lay.wheel_bodies
        # masses are read at every use: an oracle model's payload may change mid-run
        self._subtree_mass = m.body_subtreemass
        self._gravity = np.array(m.opt.gravity)
        self._jacp = np.zeros((3, m.nv))
        self._jacr = np.zeros((3, m.nv))
        self._jacp_dot = np.zeros((3, m.nv))
        self._jacr_dot = np.zeros((3, m.nv))
        self.qvel = np.zeros(m.nv)
        self.qacc0 = np.zeros(m.nv)
        self.psid = 0.0
        self.heading = np.eye(3)
        self._memo: dict[object, tuple[Array, ...]] = {}
        # views on MuJoCo's buffers (an attribute read makes a new view: ~1 us each)
        self._qpos, self._qvel, self._qacc = self.data.qpos, self.data.qvel, self.data.qacc
        self._xpos, self._site_xpos = self.data.xpos, self.data.site_xpos
        self._xipos, self._subtree_com = self.data.xipos, self.data.subtree_com
        self._subtree_linvel, self._cfrc_int = self.data.subtree_linvel, self.data.cfrc_int
        self._site_body = m.site_bodyid.copy()
        self._planar = lay.planar
        self._index_psi = lay.index_psi

    def update(self, robot: RobotModel) -> None:
        m, d = self.model, self.data
        qpos, qvel = robot.full_state(robot.q, robot.nu, robot.data.xpos[self._base, :2])
        self._qpos[: self._nq] = qpos
        self._qvel[: self._nv] = qvel
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_comVel(m, d)
        self.qvel = self._qvel
        # qacc = J_tf nu_dot + Jdot_tf nu, at nu_dot = 0 (J_tf depends on psi, q1 only)
        self.qacc0[: self._nv] = robot.Jdot_tf_nu
        self.psid = 0.0 if self._planar else float(robot.nu[self._index_psi])
        self.heading = robot.heading_rotation
        self._memo.clear()

    def point_motion(self, body: int, point: Array) -> tuple[Array, Array]:
        """World velocity and drift acceleration of ``point`` (world) attached to ``body``."""
        m, d = self.model, self.data
        mujoco.mj_jac(m, d, self._jacp, None, point, body)
        mujoco.mj_jacDot(m, d, self._jacp_dot, None, point, body)
        return self._jacp @ self.qvel, self._jacp @ self.qacc0 + self._jacp_dot @ self.qvel

    def site_motion(self, site: int) -> tuple[Array, Array, Array, Array, Array]:
        """``(position, velocity, drift acceleration, angular velocity, angular drift)`` of a
        site in world (memoised per update)."""
        key = ("site", site)
        if key not in self._memo:
            m, d = self.model, self.data
            body = int(self._site_body[site])
            position = self._site_xpos[site].copy()
            mujoco.mj_jac(m, d, self._jacp, self._jacr, position, body)
            mujoco.mj_jacDot(m, d, self._jacp_dot, self._jacr_dot, position, body)
            qvel, qacc0 = self.qvel, self.qacc0
            self._memo[key] = (
                position,
                self._jacp @ qvel,
                self._jacp @ qacc0 + self._jacp_dot @ qvel,
                self._jacr @ qvel,
                self._jacr @ qacc0 + self._jacr_dot @ qvel,
            )
        return self._memo[key]  # type: ignore[return-value]

    def origin_motion(self) -> tuple[Array, Array, Array]:
        """``(position, velocity, drift acceleration)`` of the axle midpoint in world."""
        key = "origin"
        if key not in self._memo:
            origin = self._xpos[self._base].copy()
            self._memo[key] = (origin, *self.point_motion(self._base, origin))
        return self._memo[key]  # type: ignore[return-value]

    def com_motion(self) -> tuple[Array, Array, Array]:
        """``(position, velocity, drift acceleration)`` of the body's CoM (wheels excluded)."""
        key = "com"
        if key not in self._memo:
            m, d = self.model, self.data
            base, (wl, wr) = self._base, self._wheels
            # body = the base's subtree minus the two wheels (leaves): a 3-row weighted sum
            rows = [base, wl, wr]
            weights = self._subtree_mass[rows] * np.array([1.0, -1.0, -1.0])
            mass = weights[0] + weights[1] + weights[2]
            position = weights @ np.concatenate((self._subtree_com[base][None],
                                                 self._xipos[[wl, wr]])) / mass  # fmt: skip
            mujoco.mj_subtreeVel(m, d)
            velocity = weights @ self._subtree_linvel[rows] / mass
            self._qacc[:] = self.qacc0
            mujoco.mj_rnePostConstraint(m, d)
            force = self._cfrc_int[base, 3:] - self._cfrc_int[wl, 3:] - self._cfrc_int[wr, 3:]
            self._memo[key] = (position, velocity, force / mass + self._gravity)
        return self._memo[key]  # type: ignore[return-value]

    def relative_drift(self, position: Array, velocity: Array, acceleration: Array
                       ) -> tuple[Array, Array, Array]:  # fmt: skip
        """A world point's position, velocity and drift acceleration relative to the axle
        midpoint in the axle frame (which turns at ``omega = psid e_z``)::

            rel   = Rh^T (p - p_o)
            rel'  = Rh^T (v - v_o) - omega x rel
            rel'' = Rh^T (a - a_o) - 2 omega x Rh^T (v - v_o) + omega x (omega x rel)
        """
        origin, v_o, a_o = self.origin_motion()
        Rt = self.heading.T
        rel = Rt @ (position - origin)
        u = Rt @ (velocity - v_o)
        w = self.psid
        # omega x v = w (-v_y, v_x, 0)
        rel_d = u - w * np.array([-rel[1], rel[0], 0.0])
        rel_dd = Rt @ (acceleration - a_o) - 2.0 * w * np.array([-u[1], u[0], 0.0])
        rel_dd += w * w * np.array([-rel[0], -rel[1], 0.0])
        return rel, rel_d, rel_dd
