"""Velocities and drift accelerations of task points at the robot's idealised state.

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
(``controllers.low_level.tasks``) turn these world quantities into axle-frame drifts.

Why the idealised state and not the robot's own: the measured state leaves the manifold by
~1e-5 rad and ~2e-3 m/s (contact compliance: roll, vertical speed), which the minimal model
ignores; the finite difference never saw them, and neither does this.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
from numba import njit
from numpy.typing import NDArray

from wip_gym import mujoco_c as mjc
from wip_gym.minimal_kernels import idealised_state
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]


Vec = tuple[float, float, float]


def _less_wheels(
    M: float, c: list[float], m_l: float, lw: list[float], m_r: float, rw: list[float], mass: float
) -> Vec:
    """``(M c - m_l lw - m_r rw) / mass`` per component (spelled out: a generator costs more
    than the arithmetic)."""
    return (
        (M * c[0] - m_l * lw[0] - m_r * rw[0]) / mass,
        (M * c[1] - m_l * lw[1] - m_r * rw[1]) / mass,
        (M * c[2] - m_l * lw[2] - m_r * rw[2]) / mass,
    )


@njit(cache=True)
def idealise(
    model: int,
    probe_data: int,
    q: np.ndarray,
    nu: np.ndarray,
    axle_x: float,
    axle_y: float,
    layout: np.ndarray,
    body_qpos: np.ndarray,
    body_dof: np.ndarray,
    wheel_radius: float,
    wheel_separation: float,
    probe_qpos: np.ndarray,
    probe_qvel: np.ndarray,
    probe_qacc0: np.ndarray,
    Jdot_tf_nu: np.ndarray,
) -> None:
    """The probe's state for the robot's minimal state ``(q, nu)``: ``full_state(q, nu)`` at
    the axle's position into the probe's ``qpos``, ``qvel`` (the robot's own entries), its
    kinematics, ``mj_comPos`` and ``mj_comVel`` (``wip_gym.mujoco_c``), and ``qacc_0 = Jdot_tf
    nu`` (``qacc = J_tf nu_dot + Jdot_tf nu`` at ``nu_dot = 0``; over every dof of the model, a
    cup's too: zero). The one-call step's (the fast path); :meth:`MotionProbe.idealise` makes
    the same calls through MuJoCo's bindings."""
    idealised_state(
        q,
        nu,
        axle_x,
        axle_y,
        layout,
        body_qpos,
        body_dof,
        wheel_radius,
        wheel_separation,
        probe_qpos,
        probe_qvel,
    )
    mjc.mj_kinematics(model, probe_data)
    mjc.mj_comPos(model, probe_data)
    mjc.mj_comVel(model, probe_data)
    probe_qacc0[:] = Jdot_tf_nu


class MotionProbe:
    """World velocities and drift accelerations (``nu_dot = 0``) at ``full_state(q, nu)``.

    Call :meth:`update` once per control step after ``robot.update``; then
    :meth:`site_motion`, :meth:`body_point_motion`, :meth:`point_motion`, :meth:`origin_motion`,
    :meth:`com_motion` and :meth:`relative_drift`
    read it (memoised). Three-vectors are tuples of Python floats: at this size scalar
    arithmetic costs a tenth of a NumPy call.
    """

    def __init__(self, robot: RobotModel) -> None:
        m = robot.model
        self.model = m
        self.data = mujoco.MjData(m)
        lay = robot.layout
        self._nq, self._nv = lay.nq, lay.nv
        self._base = lay.base_body
        self._wheels = lay.wheel_bodies
        self._rows = [lay.base_body, *lay.wheel_bodies]
        self._gravity: Vec = tuple(float(v) for v in m.opt.gravity)  # type: ignore[assignment]
        # [jacp; jacr] and its time derivative in one buffer each: three products per point
        self._jac = np.zeros((6, m.nv))
        self._jac_dot = np.zeros((6, m.nv))
        self.qvel = np.zeros(m.nv)
        self.qacc0 = np.zeros(m.nv)
        self.psid = 0.0
        self.heading = np.eye(3)
        self._c, self._s = 1.0, 0.0
        self._memo: dict[object, tuple[Vec, ...]] = {}
        self._site_body = m.site_bodyid.copy()
        self._planar = lay.planar
        self._index_psi = lay.index_psi
        self._layout_ints, self._body_qpos, self._body_dof = lay.kernel_arrays()
        self._wheel_radius, self._wheel_separation = lay.wheel_radius, lay.wheel_separation
        self._bind_views()

    def _bind_views(self) -> None:
        """Views on MuJoCo's buffers (an attribute read makes a new view: ~1 us each); made
        again after a copy or an unpickling, whose views would point at the old arrays. Masses
        are read at every use: an oracle model's payload may change mid-run."""
        d = self.data
        self._qpos, self._qvel, self._qacc = d.qpos, d.qvel, d.qacc
        self._xpos, self._site_xpos = d.xpos, d.site_xpos
        self._xipos, self._subtree_com = d.xipos, d.subtree_com
        self._subtree_linvel, self._cfrc_int = d.subtree_linvel, d.cfrc_int
        self._subtree_mass = self.model.body_subtreemass

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)
        self._bind_views()

    def update(self, robot: RobotModel) -> None:
        self.idealise(robot)
        self.qvel = self._qvel
        self.psid = 0.0 if self._planar else float(robot.nu[self._index_psi])
        self.heading = robot.heading_rotation
        self._c, self._s = float(self.heading[0, 0]), float(self.heading[1, 0])
        self._memo.clear()

    def idealise(self, robot: RobotModel) -> None:
        """:func:`idealise` for ``robot``'s current state, through MuJoCo's Python bindings
        (the same calls in the same order: the same results to the bit)."""
        x, y = robot.data.xpos[self._base, :2].tolist()
        idealised_state(
            robot.q,
            robot.nu,
            x,
            y,
            self._layout_ints,
            self._body_qpos,
            self._body_dof,
            self._wheel_radius,
            self._wheel_separation,
            self._qpos[: self._nq],
            self._qvel[: self._nv],
        )
        m, d = self.model, self.data
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_comVel(m, d)
        self.qacc0[:] = robot.Jdot_tf_nu

    def point_motion(self, position: Array, body: int) -> tuple[Vec, Vec, Vec, Vec]:
        """Linear velocity, drift acceleration, angular velocity, angular drift (world) of the
        point at world ``position`` (at the probe's state) attached to ``body``: ``jac qvel``
        and ``jac qacc_0 + jacDot qvel``."""
        m, d, jac, jac_dot = self.model, self.data, self._jac, self._jac_dot
        mujoco.mj_jac(m, d, jac[:3], jac[3:], position, body)
        mujoco.mj_jacDot(m, d, jac_dot[:3], jac_dot[3:], position, body)
        v = (jac @ self.qvel).tolist()
        a = (jac @ self.qacc0 + jac_dot @ self.qvel).tolist()
        return (v[0], v[1], v[2]), (a[0], a[1], a[2]), (v[3], v[4], v[5]), (a[3], a[4], a[5])

    def site_motion(self, site: int) -> tuple[Vec, Vec, Vec, Vec, Vec]:
        """``(position, velocity, drift acceleration, angular velocity, angular drift)`` of a
        site in world (memoised per update)."""
        key = ("site", site)
        if key not in self._memo:
            position = self._site_xpos[site]
            v, a, w, w_dot = self.point_motion(position, int(self._site_body[site]))
            p = position.tolist()
            self._memo[key] = ((p[0], p[1], p[2]), v, a, w, w_dot)
        return self._memo[key]  # type: ignore[return-value]

    def body_point_motion(
        self, body: int, offset: Any = (0.0, 0.0, 0.0)
    ) -> tuple[Vec, Vec, Vec, Vec, Vec]:
        """:meth:`site_motion` for a point fixed on a body, ``offset`` in the body's frame (as
        ``controllers.low_level.tasks.body_point_in_axle_frame`` takes it)."""
        offset = np.asarray(offset, dtype=float)
        key = ("body", body, *offset.tolist())
        if key not in self._memo:
            d = self.data
            position = d.xpos[body] + d.xmat[body].reshape(3, 3) @ offset
            v, a, w, w_dot = self.point_motion(position, body)
            p = position.tolist()
            self._memo[key] = ((p[0], p[1], p[2]), v, a, w, w_dot)
        return self._memo[key]  # type: ignore[return-value]

    def origin_motion(self) -> tuple[Vec, Vec, Vec]:
        """``(position, velocity, drift acceleration)`` of the axle midpoint in world."""
        key = "origin"
        if key not in self._memo:
            origin = self._xpos[self._base]
            v, a, _, _ = self.point_motion(origin, self._base)
            p = origin.tolist()
            self._memo[key] = ((p[0], p[1], p[2]), v, a)
        return self._memo[key]  # type: ignore[return-value]

    def com_motion(self) -> tuple[Vec, Vec, Vec]:
        """``(position, velocity, drift acceleration)`` of the body's CoM (wheels excluded):
        the base's subtree minus the two wheels (leaves)."""
        key = "com"
        if key not in self._memo:
            m, d = self.model, self.data
            base, (wl, wr) = self._base, self._wheels
            M, m_l, m_r = self._subtree_mass[self._rows].tolist()
            mass = M - m_l - m_r
            (c, lw, rw) = (
                self._subtree_com[base].tolist(),
                self._xipos[wl].tolist(),
                self._xipos[wr].tolist(),
            )
            position = _less_wheels(M, c, m_l, lw, m_r, rw, mass)
            mujoco.mj_subtreeVel(m, d)
            c, lw, rw = self._subtree_linvel[self._rows].tolist()
            velocity = _less_wheels(M, c, m_l, lw, m_r, rw, mass)
            self._qacc[:] = self.qacc0
            mujoco.mj_rnePostConstraint(m, d)
            # the linear part of a subtree's net force is sum m_i (a_i - g)
            c, lw, rw = self._cfrc_int[self._rows, 3:].tolist()
            g = self._gravity
            drift = (
                (c[0] - lw[0] - rw[0]) / mass + g[0],
                (c[1] - lw[1] - rw[1]) / mass + g[1],
                (c[2] - lw[2] - rw[2]) / mass + g[2],
            )
            self._memo[key] = (position, velocity, drift)  # type: ignore[assignment]
        return self._memo[key]  # type: ignore[return-value]

    def to_axle(self, v: Vec) -> Vec:
        """``Rh^T v``."""
        c, s = self._c, self._s
        return (c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2])

    def relative_drift(
        self, position: Vec, velocity: Vec, acceleration: Vec
    ) -> tuple[Vec, Vec, Vec]:
        """A world point's position, velocity and drift acceleration relative to the axle
        midpoint in the axle frame (which turns at ``omega = psid e_z``)::

            rel   = Rh^T (p - p_o)
            rel'  = Rh^T (v - v_o) - omega x rel
            rel'' = Rh^T (a - a_o) - 2 omega x Rh^T (v - v_o) + omega x (omega x rel)
        """
        p_o, v_o, a_o = self.origin_motion()
        rel = self.to_axle((position[0] - p_o[0], position[1] - p_o[1], position[2] - p_o[2]))
        u = self.to_axle((velocity[0] - v_o[0], velocity[1] - v_o[1], velocity[2] - v_o[2]))
        a = self.to_axle(
            (acceleration[0] - a_o[0], acceleration[1] - a_o[1], acceleration[2] - a_o[2])
        )
        w = self.psid
        rel_d = (u[0] + w * rel[1], u[1] - w * rel[0], u[2])
        rel_dd = (
            a[0] + 2.0 * w * u[1] - w * w * rel[0],
            a[1] - 2.0 * w * u[0] - w * w * rel[1],
            a[2],
        )
        return rel, rel_d, rel_dd
