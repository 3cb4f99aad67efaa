"""The robot in minimal coordinates: paper eq. ``dyn`` built from MuJoCo.

A WIP humanoid on flat ground keeps its wheels rolling without slip (and, in 3-D, without side
slip), its axle at the wheel radius and its axle level. What is left are the minimal coordinates
(docs/DESIGN.md §4):

* 3-D: ``q = [x, psi, q1, q2, ..., qn]``, velocities ``nu = [xd, psid, q1d, ..., qnd]``;
* planar: ``q = [x, q1, ..., qn]``, ``nu = [xd, q1d, ..., qnd]``;

with ``x`` the distance rolled along the heading (3-D: wheel odometry
``r (phi_L + phi_R) / 2`` with the absolute wheel angles, joint angle plus base pitch; planar:
the base slide), ``psi`` the heading, ``q1`` the base pitch from vertical and ``q2..qn`` the body
joints. MuJoCo's velocities are ``qvel = J_tf nu`` (the paper's transform Jacobian), and

    A nu_dot + h = B tau                                        (paper eq. ``dyn``)
    A = J_tf^T M J_tf,   h = J_tf^T (M Jdot_tf nu + c - f_passive),   B = J_tf^T S

with ``M`` MuJoCo's mass matrix, ``c`` its bias (Coriolis, centrifugal, gravity), ``f_passive``
its passive forces (joint damping: the paper's friction ``Gamma_fric``) and ``S`` the actuator
map. The same update gives the body CoM in the axle frame, ``theta``, ``thetad`` and the WIPM
parameters ``lambda(q)`` (paper section "Simplified Model"; docs/ERRATA.md §1 for what they mean).

``RobotModel`` owns an ``MjData``; :meth:`RobotModel.update` computes everything for one state,
once per control step, and the properties read the cache.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from wip_gym import minimal_kernels as kernels
from wip_gym import mujoco_c
from wip_gym.minimal_kernels import (
    all_finite,
    idealised_state,
    inertia_about_point,
    robot_update_at,
    update_dynamics,
    update_kinematics,
)

Array = NDArray[np.float64]
_ArrayT = TypeVar("_ArrayT", bound=np.ndarray)

_FREE = int(mujoco.mjtJoint.mjJNT_FREE)
_SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)
_HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)

#: the order of the scalars of :meth:`RobotModel.wipm_values`: the fields of
#: ``controllers.simplified.wipm.WIPMParams`` but its ``inertia_body``
WIPM_SCALARS = (
    "body_mass",
    "com_distance",
    "com_lateral",
    "wheel_mass",
    "wheel_inertia",
    "wheel_inertia_transverse",
    "wheel_damping",
    "wheel_radius",
    "wheel_separation",
    "gravity",
)


@dataclass(frozen=True)
class RobotLayout:
    """Where a wip-gym robot lives inside a MuJoCo model (found from the names of
    ``assets/mjcf/README.md``).

    Attributes:
        planar: base on slide x, slide z, pitch hinge (else a free joint).
        nq, nv: the robot's own position and velocity sizes (its joints come first in the model).
        root_qpos, root_dof: first qpos / dof address of the root joint(s).
        wheel_qpos, wheel_dof: addresses of ``wheel_left``, ``wheel_right``.
        body_qpos, body_dof: addresses of the body joints ``q2..qn`` in tree order.
        wheel_radius, wheel_separation: from the wheel collision geoms and wheel positions.
        base_body: id of ``base``; wheel_bodies: ids of the wheels; body_bodies: ids of every
            robot body except the wheels (the "body" of the paper: its CoM defines ``theta``).
        wheel_actuators: actuator ids of the wheels (left, right); joint_actuators: actuator id of
            each body joint, in ``body_dof`` order.
    """

    planar: bool
    nq: int
    nv: int
    root_qpos: int
    root_dof: int
    wheel_qpos: tuple[int, int]
    wheel_dof: tuple[int, int]
    body_qpos: tuple[int, ...]
    body_dof: tuple[int, ...]
    wheel_radius: float
    wheel_separation: float
    base_body: int
    wheel_bodies: tuple[int, int]
    body_bodies: tuple[int, ...]
    wheel_actuators: tuple[int, int]
    joint_actuators: tuple[int, ...]

    @property
    def n_min(self) -> int:
        """Number of minimal coordinates: ``2 + n`` in 3-D, ``1 + n`` planar (n body joints
        including the base pitch q1)."""
        return (2 if not self.planar else 1) + 1 + len(self.body_dof)

    @property
    def index_x(self) -> int:
        return 0

    @property
    def index_psi(self) -> int | None:
        return None if self.planar else 1

    @property
    def index_q1(self) -> int:
        return 1 if self.planar else 2

    def kernel_arrays(self) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
        """The layout as the compiled kernels take it (``wip_gym.minimal_kernels``):
        ``[planar, root_qpos, root_dof, wheel_qpos..., wheel_dof...]``, ``body_qpos``,
        ``body_dof`` (new int64 arrays)."""
        ints = np.array(
            [self.planar, self.root_qpos, self.root_dof, *self.wheel_qpos, *self.wheel_dof],
            dtype=np.int64,
        )
        return (
            ints,
            np.array(self.body_qpos, dtype=np.int64),
            np.array(self.body_dof, dtype=np.int64),
        )

    @classmethod
    def from_model(cls, model: mujoco.MjModel) -> RobotLayout:
        """Read the layout of the robot in ``model``; raise ``ValueError`` where the contract of
        ``assets/mjcf/README.md`` is broken."""

        def body_id(name: str) -> int:
            i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
            if i < 0:
                raise ValueError(f"robot model has no body {name!r}")
            return int(i)

        def joint_id(name: str) -> int:
            i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
            if i < 0:
                raise ValueError(f"robot model has no joint {name!r}")
            return int(i)

        base = body_id("base")
        robot_bodies = [b for b in range(model.nbody) if model.body_rootid[b] == base]
        wheels = (body_id("wheel_left"), body_id("wheel_right"))
        planar = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "root") < 0
        if planar:
            roots = [joint_id(n) for n in ("root_x", "root_z", "root_pitch")]
            expected = [_SLIDE, _SLIDE, _HINGE]
            if [int(model.jnt_type[j]) for j in roots] != expected:
                raise ValueError("planar root must be slide root_x, slide root_z, hinge root_pitch")
            if list(model.jnt_dofadr[roots]) != [0, 1, 2]:
                raise ValueError("planar root joints must be the model's first three dofs")
        else:
            roots = [joint_id("root")]
            if int(model.jnt_type[roots[0]]) != _FREE:
                raise ValueError("joint 'root' must be a free joint")
            if model.jnt_dofadr[roots[0]] != 0:
                raise ValueError("the free joint 'root' must be the model's first joint")
        wheel_joints = (joint_id("wheel_left"), joint_id("wheel_right"))
        robot_joints = [j for j in range(model.njnt) if model.jnt_bodyid[j] in robot_bodies]
        body_joints = [j for j in robot_joints if j not in roots and j not in wheel_joints]
        for j in body_joints:
            if int(model.jnt_type[j]) not in (_HINGE, _SLIDE):
                raise ValueError(f"body joint {model.joint(j).name!r} must be a hinge or slide")
        body_joints.sort(key=lambda j: model.jnt_dofadr[j])
        dof_counts = {j: 6 if int(model.jnt_type[j]) == _FREE else 1 for j in robot_joints}
        nv = sum(dof_counts.values())
        nq = sum(7 if n == 6 else 1 for n in dof_counts.values())
        robot_dofs = sorted(
            int(model.jnt_dofadr[j]) + k for j in robot_joints for k in range(dof_counts[j])
        )
        if robot_dofs != list(range(nv)):
            raise ValueError(
                "the robot's joints must come first in the model (before any free object)"
            )

        geom_left = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "wheel_left")
        if geom_left < 0 or int(model.geom_type[geom_left]) != int(mujoco.mjtGeom.mjGEOM_SPHERE):
            raise ValueError("wheel collision geom 'wheel_left' must be a sphere")
        radius = float(model.geom_size[geom_left, 0])
        separation = float(abs(model.body_pos[wheels[0], 1] - model.body_pos[wheels[1], 1]))

        actuator_of_dof: dict[int, int] = {}
        for a in range(model.nu):
            if int(model.actuator_trntype[a]) != int(mujoco.mjtTrn.mjTRN_JOINT):
                raise ValueError(f"actuator {model.actuator(a).name!r} must drive a joint")
            actuator_of_dof[int(model.jnt_dofadr[model.actuator_trnid[a, 0]])] = a
        wheel_dof = tuple(int(model.jnt_dofadr[j]) for j in wheel_joints)
        body_dof = tuple(int(model.jnt_dofadr[j]) for j in body_joints)
        missing = [
            model.joint(j).name
            for j in (*wheel_joints, *body_joints)
            if model.jnt_dofadr[j] not in actuator_of_dof
        ]
        if missing:
            raise ValueError(f"joints without an actuator: {missing}")

        return cls(
            planar=planar,
            nq=nq,
            nv=nv,
            root_qpos=int(model.jnt_qposadr[roots[0]]),
            root_dof=int(model.jnt_dofadr[roots[0]]),
            wheel_qpos=(
                int(model.jnt_qposadr[wheel_joints[0]]),
                int(model.jnt_qposadr[wheel_joints[1]]),
            ),
            wheel_dof=(wheel_dof[0], wheel_dof[1]),
            body_qpos=tuple(int(model.jnt_qposadr[j]) for j in body_joints),
            body_dof=body_dof,
            wheel_radius=radius,
            wheel_separation=separation,
            base_body=base,
            wheel_bodies=wheels,
            body_bodies=tuple(b for b in robot_bodies if b not in wheels),
            wheel_actuators=(actuator_of_dof[wheel_dof[0]], actuator_of_dof[wheel_dof[1]]),
            joint_actuators=tuple(actuator_of_dof[d] for d in body_dof),
        )


@dataclass(frozen=True)
class WIPMParameters:
    """``lambda(q)``: the simplified model's parameters at one state (paper section
    "Simplified Model", with the meanings of docs/ERRATA.md §1).

    Attributes:
        body_mass: ``M``, the mass of everything but the wheels (kg).
        com: body CoM in the axle frame ``(X_com, Y_com, Z_com)`` (m).
        com_distance: ``L = sqrt(X_com^2 + Z_com^2)``, the pendulum length (m).
        theta, thetad: CoM pitch about the wheel axis from vertical, and its rate.
        pitch_inertia: ``I``, the body's inertia about the wheel axis (= ``A[q1, q1]``) (kg m^2).
        inertia_axle: the body's inertia tensor about the axle midpoint in the axle frame.
        wheel_mass, wheel_inertia: mass and axial inertia of ONE wheel.
        wheel_inertia_transverse: a wheel's inertia about a diameter.
        wheel_damping: viscous damping of ONE wheel joint (N m s / rad).
        wheel_radius, wheel_separation: ``r`` and the distance between the wheels.
        gravity: ``g`` (m/s^2), MuJoCo's.
    """

    body_mass: float
    com: Array
    com_distance: float
    theta: float
    thetad: float
    pitch_inertia: float
    inertia_axle: Array
    wheel_mass: float
    wheel_inertia: float
    wheel_inertia_transverse: float
    wheel_damping: float
    wheel_radius: float
    wheel_separation: float
    gravity: float


class RobotModel:
    """Minimal-coordinate kinematics and dynamics of a wip-gym robot, cached per state.

    Args:
        model: a MuJoCo model that follows ``assets/mjcf/README.md`` (extra free objects such as
            a cup may follow the robot's joints; they do not enter the robot's dynamics).

    Use ``update(qpos, qvel)`` once per control step (``qpos``/``qvel`` are the robot's own
    ``nq``/``nv`` entries, as in an observation), then read ``q``, ``nu``, ``J_tf``,
    ``Jdot_tf_nu``, ``A``, ``h``, ``B``, ``com``, ``theta``, ``thetad``, ``J_theta``, ...
    """

    def __init__(self, model: mujoco.MjModel) -> None:
        self._model = model
        self._data = mujoco.MjData(model)
        self.layout = RobotLayout.from_model(model)
        lay = self.layout
        nv, n = model.nv, lay.n_min
        self._M = np.zeros((nv, nv))
        self._bias = np.zeros(nv)
        self._J = np.zeros((nv, n))
        self._Jdot_nu = np.zeros(nv)
        self._S = np.zeros((nv, model.nu))
        for a in range(model.nu):
            self._S[model.jnt_dofadr[model.actuator_trnid[a, 0]], a] = model.actuator_gear[a, 0]
        self._jacp = np.zeros((3, nv))
        self._jac_wheels = np.zeros((2, 3, nv))
        self._jac_origin = np.zeros((3, nv))
        self._bind_views()
        # the state, copied in each update: the compiled update sees one array type whatever
        # the caller passes (read-only or strided arrays would each compile it again)
        self._qpos_in = np.zeros(lay.nq)
        self._qvel_in = np.zeros(lay.nv)
        self._body_ids = np.array(lay.body_bodies, dtype=np.int64)
        self._layout_ints, self._body_qpos, self._body_dof = lay.kernel_arrays()
        self._bodies = np.array([lay.base_body, *lay.wheel_bodies], dtype=np.int64)
        self._heading: Array | None = _read_only(np.eye(3))
        self._cos_psi, self._sin_psi = 1.0, 0.0
        self._q = np.zeros(n)
        self._nu = np.zeros(n)
        first_body = 3 if not lay.planar else 2
        # constant entries of J_tf
        r, sep = lay.wheel_radius, lay.wheel_separation
        for k, dof in enumerate(lay.body_dof):
            self._J[dof, first_body + k] = 1.0
        for dof in lay.wheel_dof:
            self._J[dof, lay.index_x] = 1.0 / r
            self._J[dof, lay.index_q1] = -1.0
        if lay.planar:
            self._J[lay.root_dof + 0, lay.index_x] = 1.0
            self._J[lay.root_dof + 2, lay.index_q1] = 1.0
        else:
            self._J[lay.wheel_dof[0], 1] = -sep / (2.0 * r)
            self._J[lay.wheel_dof[1], 1] = sep / (2.0 * r)
            self._J[lay.root_dof + 4, 2] = 1.0
        self._J_pattern = _read_only(transform_pattern(self._J, lay))
        # the compiled update's outputs, written in place; the properties hand out copies made
        # at their first read after an update (so that what a caller keeps stays as it was)
        self._scalars = np.zeros(len(kernels.UPDATE_SCALARS))
        self._com_buffer = np.zeros(3)
        self._J_com_buffer = np.zeros((3, n))
        self._J_theta_buffer = np.zeros(n)
        self._A_buffer = np.zeros((n, n))
        self._h_buffer = np.zeros(n)
        self._B_buffer = np.zeros((n, model.nu))
        self._forget_copies()
        self._wheel_frame = np.zeros(9)  # wipm_values' (mju_quat2Mat of the wheel's iquat)
        self._fast = mujoco_c.fast_path()
        self._bind_tables()
        self._updated = False
        self._has_dynamics = False
        # per-state memo for quantities computed by users of this model (task Jacobians, ...);
        # cleared by every update
        self.cache: dict[object, object] = {}

    @property
    def model(self) -> mujoco.MjModel:
        """The MuJoCo model, fixed for this object's life (its compiled calls hold views and
        addresses of its buffers): change its values in place (a mass, a gain); for another
        model make another ``RobotModel``."""
        return self._model

    @property
    def data(self) -> mujoco.MjData:
        """This object's own MuJoCo data (fixed, as :attr:`model`)."""
        return self._data

    def _bind_views(self) -> None:
        """Views on MuJoCo's buffers (an attribute read makes a new view: ~1 us each), made
        again after a copy or an unpickling (whose views would point at the old arrays). Masses
        are read at every update (an env may change them: payload, randomisation)."""
        d, model = self.data, self.model
        self._mj_qpos, self._mj_qvel = d.qpos, d.qvel
        self._mj_xpos, self._mj_xipos, self._mj_xmat = d.xpos, d.xipos, d.xmat
        self._mj_body_mass, self._mj_subtree_mass = model.body_mass, model.body_subtreemass
        self._mj_qfrc_passive = d.qfrc_passive

    def _bind_tables(self) -> None:
        """The tables of addresses (``wip_gym.array_table``) of the update
        (``minimal_kernels.UPDATE``) and of :meth:`wipm_values` (``minimal_kernels.WIPM``):
        their buffers and MuJoCo's, made once, so that a compiled call unboxes one array. Made
        again with the views after a copy or an unpickling (their addresses would be the old
        model's). On the fast path the update's table holds the model's and data's addresses
        too (``wip_gym.mujoco_c.addresses``)."""
        m, d, lay = self.model, self.data, self.layout
        self._wheel_iquat = m.body_iquat[lay.wheel_bodies[0]]
        self._wipm_table = kernels.WIPM.table(
            {
                "ids": np.array([lay.base_body, lay.wheel_bodies[0], lay.wheel_dof[0]], np.int64),
                "ximat": d.ximat,
                "xipos": self._mj_xipos,
                "xpos": self._mj_xpos,
                "body_inertia": m.body_inertia,
                "wheel_frame": self._wheel_frame,
                "body_mass": self._mj_body_mass,
                "dof_damping": m.dof_damping,
                "gravity": m.opt.gravity,
                "body_ids": self._body_ids,
            }
        )
        addresses = mujoco_c.addresses(m, d) if self._fast else (0, 0)
        self._update_table = kernels.UPDATE.table(
            {
                "mujoco": np.array(addresses, dtype=np.int64),
                "constants": np.array([lay.wheel_radius]),
                "qpos": self._qpos_in,
                "qvel": self._qvel_in,
                "data_qpos": self._mj_qpos,
                "data_qvel": self._mj_qvel,
                "xmat": self._mj_xmat,
                "xpos": self._mj_xpos,
                "xipos": self._mj_xipos,
                "qfrc_passive": self._mj_qfrc_passive,
                "body_mass": self._mj_body_mass,
                "subtree_mass": self._mj_subtree_mass,
                "bodies": self._bodies,
                "body_ids": self._body_ids,
                "layout": self._layout_ints,
                "body_qpos": self._body_qpos,
                "body_dof": self._body_dof,
                "q": self._q,
                "nu": self._nu,
                "J": self._J,
                "J_pattern": self._J_pattern,
                "Jdot_nu": self._Jdot_nu,
                "jac_subtree": self._jacp,
                "jac_wheels": self._jac_wheels,
                "jac_origin": self._jac_origin,
                "M": self._M,
                "bias": self._bias,
                "S": self._S,
                "scalars": self._scalars,
                "com": self._com_buffer,
                "J_com": self._J_com_buffer,
                "J_theta": self._J_theta_buffer,
                "A": self._A_buffer,
                "h": self._h_buffer,
                "B": self._B_buffer,
            }
        )

    @property
    def fast_path(self) -> bool:
        """Whether this model's update takes the compiled fast path (MuJoCo's C functions from
        compiled code, ``wip_gym.mujoco_c``) or the readable one (MuJoCo's Python bindings,
        then the same compiled arithmetic: the same results to the bit). Chosen when it is
        made (``wip_gym.mujoco_c.fast_path``); a task QP on this robot follows it."""
        return self._fast

    def __getstate__(self) -> dict[str, object]:
        state = self.__dict__.copy()
        state.pop("_update_table", None)  # addresses: made again by __setstate__
        state.pop("_wipm_table", None)
        return state

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)
        # a process where the fast path cannot run (or is switched off) takes the readable one
        self._fast = self._fast and mujoco_c.fast_path()
        self._bind_views()
        self._bind_tables()
        # NumPy's pickling and deepcopy do not keep the read-only flag (and a writable array is
        # another signature for numba: the two-call task rows and wipm_values would compile
        # again)
        _read_only(self._J_pattern)
        if self._heading is not None:
            _read_only(self._heading)

    # ------------------------------------------------------------------ state
    def update(self, qpos: ArrayLike, qvel: ArrayLike, *, dynamics: bool = True) -> None:
        """Compute everything for the state ``(qpos, qvel)`` (the robot's own coordinates).

        With ``dynamics=False`` only the kinematic quantities (minimal coordinates, ``J_tf``,
        CoM, ``theta``, ``thetad``) are computed; ``A``, ``h``, ``B`` are then unavailable.
        """
        lay = self.layout
        qpos = np.asarray(qpos, dtype=float)
        qvel = np.asarray(qvel, dtype=float)
        if qpos.shape != self._qpos_in.shape or qvel.shape != self._qvel_in.shape:
            raise ValueError(
                f"expected qpos of shape ({lay.nq},) and qvel ({lay.nv},), "
                f"got {qpos.shape}, {qvel.shape}"
            )
        # copied first: the compiled update sees one array type (the copies are scratch, read
        # only by it), and checks them before it computes anything
        self._qpos_in[:] = qpos
        self._qvel_in[:] = qvel
        if self._fast:
            if not robot_update_at(self._update_table.rows, dynamics):
                raise ValueError("qpos/qvel contain NaN or inf")
        else:
            self._update_through_bindings(dynamics)
        self.cache.clear()
        (
            self._psi,
            self._psid,
            self._cos_psi,
            self._sin_psi,
            self._body_mass,
            self._theta,
            self._thetad,
            self._x,
            self._xd,
            self._axle_x,
            self._axle_y,
        ) = self._scalars.tolist()
        self._forget_copies()
        # the base origin's linear Jacobian, kept for the tasks (site_in_axle_frame)
        self.cache["origin_jacobian"] = self._jac_origin
        self._updated = True
        self._has_dynamics = dynamics

    def _update_through_bindings(self, dynamics: bool) -> None:
        """:meth:`update`'s readable path: :func:`minimal_kernels.robot_update_at`'s MuJoCo
        calls through the Python bindings, in its order, around the same compiled arithmetic
        (``update_kinematics``, ``update_dynamics``)."""
        if not all_finite(self._qpos_in, self._qvel_in):
            raise ValueError("qpos/qvel contain NaN or inf")
        m, d, lay = self.model, self.data, self.layout
        self._mj_qpos[: lay.nq] = self._qpos_in
        self._mj_qvel[: lay.nv] = self._qvel_in
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        base, (left, right) = lay.base_body, lay.wheel_bodies
        mujoco.mj_jacSubtreeCom(m, d, self._jacp, base)
        for k, wheel in enumerate((left, right)):
            mujoco.mj_jac(m, d, self._jac_wheels[k], None, self._mj_xipos[wheel], wheel)
        mujoco.mj_jac(m, d, self._jac_origin, None, self._mj_xpos[base], base)
        table = self._update_table.rows
        update_kinematics(table)
        if dynamics:
            mujoco.mj_crb(m, d)
            mujoco.mj_fullM(m, d, self._M)
            mujoco.mj_comVel(m, d)
            mujoco.mj_passive(m, d)
            mujoco.mj_rne(m, d, 0, self._bias)
            update_dynamics(table)

    def _forget_copies(self) -> None:
        """The properties' copies of the update's outputs, made again at their next read
        (:meth:`_kept_copy`)."""
        self._copies: dict[str, Array] = {}
        if not self.layout.planar:
            self._heading = None  # Rz(psi), made at its first read

    def _kept_copy(self, name: str, buffer: Array) -> Array:
        """This update's copy of ``buffer``, made at its first read (then the same array)."""
        copies = self._copies
        kept = copies.get(name)
        if kept is None:
            kept = copies[name] = buffer.copy()
        return kept

    def update_buffers(self) -> dict[str, Array]:
        """The compiled update's outputs that compiled callers read (the task QP's one-call
        step, ``controllers.low_level.compiled_step``): ``J_theta``, ``A``, ``h`` and
        ``scalars`` (``minimal_kernels.UPDATE_SCALARS``), written in place by every update of
        this object. Python callers: use the properties (copies that stay as they were)."""
        return {
            "J_theta": self._J_theta_buffer,
            "A": self._A_buffer,
            "h": self._h_buffer,
            "robot_scalars": self._scalars,
            "origin_jac": self._jac_origin,
        }

    @property
    def has_dynamics(self) -> bool:
        """Whether the last update computed ``A``, ``h``, ``B`` (``dynamics=True``)."""
        return self._updated and self._has_dynamics

    def _require(self) -> None:
        if not self._updated:
            raise RuntimeError("RobotModel.update(qpos, qvel) must be called first")

    def _require_dynamics(self) -> None:
        self._require()
        if not self._has_dynamics:
            raise RuntimeError("the last update had dynamics=False: A, h, B were not computed")

    # ------------------------------------------------------------- accessors
    @property
    def q(self) -> Array:
        """Minimal positions ``[x, psi, q1, ..., qn]`` (planar: ``[x, q1, ..., qn]``)."""
        self._require()
        return self._q

    @property
    def nu(self) -> Array:
        """Minimal velocities ``[xd, psid, q1d, ..., qnd]`` (planar: ``[xd, q1d, ...]``)."""
        self._require()
        return self._nu

    @property
    def J_tf(self) -> Array:
        """Transform Jacobian, ``qvel = J_tf @ nu`` (``nv x n_min``)."""
        self._require()
        return self._J

    @property
    def J_tf_pattern(self) -> NDArray[np.int64]:
        """Where :attr:`J_tf` may be nonzero, at any state: ``(2, nnz)`` row and column indices,
        column by column (read-only; the compiled products with ``J_tf`` visit only these)."""
        return self._J_pattern

    @property
    def Jdot_tf_nu(self) -> Array:
        """``Jdot_tf @ nu``: ``qacc = J_tf @ nu_dot + Jdot_tf_nu``."""
        self._require()
        return self._Jdot_nu

    @property
    def A(self) -> Array:
        """Minimal-coordinate inertia ``J_tf^T M J_tf`` (paper eq. ``dyn``). A new array per
        update (the same one within it), as are ``h``, ``B``, ``com``, ``J_com``, ``J_theta``
        and ``heading_rotation``; ``q``, ``nu``, ``J_tf`` and ``Jdot_tf_nu`` are buffers that
        every update writes in place (copy them to keep a state's values)."""
        self._require_dynamics()
        return self._kept_copy("A", self._A_buffer)

    @property
    def h(self) -> Array:
        """Bias ``J_tf^T (M Jdot_tf nu + c - f_passive)``: Coriolis, gravity, friction."""
        self._require_dynamics()
        return self._kept_copy("h", self._h_buffer)

    @property
    def B(self) -> Array:
        """Actuation ``J_tf^T S`` (``n_min x nu``): ``A nu_dot + h = B ctrl``."""
        self._require_dynamics()
        return self._kept_copy("B", self._B_buffer)

    @property
    def psi(self) -> float:
        self._require()
        return self._psi

    @property
    def heading_rotation(self) -> Array:
        """Rotation of the axle frame in world: ``Rz(psi)`` (identity for planar robots).
        Read-only, made once per update (at its first read)."""
        if self._heading is None:
            c, s = self._cos_psi, self._sin_psi
            heading = np.array((c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)).reshape(3, 3)
            self._heading = _read_only(heading)
        return self._heading

    def update_scalars(self) -> Array:
        """A copy of the last update's scalars (``minimal_kernels.UPDATE_SCALARS``: ``psi``,
        ``psid``, the heading's cosine and sine, the body mass, ``theta``, ``thetad``, ``x``,
        ``xd``, the axle's ``X0, Y0``): what a per-step record keeps, one small copy, mapped to
        WIPM states afterwards by :meth:`wipm_states`."""
        self._require()
        return self._scalars.copy()

    def wipm_states(self, scalars: ArrayLike) -> Array:
        """The WIPM states (:meth:`wipm_state`'s order) of ``scalars``: one or rows of
        :meth:`update_scalars`. ``ValueError`` for another last axis."""
        scalars = np.asarray(scalars, dtype=float)
        if scalars.shape[-1:] != self._scalars.shape:
            raise ValueError(
                f"expected rows of {len(self._scalars)} update scalars, got shape {scalars.shape}"
            )
        columns = (
            kernels.PLANAR_STATE_SCALARS if self.layout.planar else kernels.SPATIAL_STATE_SCALARS
        )
        return scalars[..., list(columns)]

    def wipm_state(self) -> Array:
        """The WIPM state of the robot (its ``lambda(q)`` part) at the last update, from the
        update's scalars: planar ``[theta, thetad, x, xd]``, 3-D ``[x, psi, theta, xd, psid,
        thetad, X0, Y0]`` (``X0, Y0`` the axle midpoint's world position). A new array."""
        self._require()
        if self.layout.planar:
            return np.array([self._theta, self._thetad, self._x, self._xd])
        return np.array(
            [
                self._x,
                self._psi,
                self._theta,
                self._xd,
                self._psid,
                self._thetad,
                self._axle_x,
                self._axle_y,
            ]
        )

    @property
    def axle_position(self) -> Array:
        """World position of the axle midpoint ``(X0, Y0, Z0)``."""
        self._require()
        return self._mj_xpos[self.layout.base_body].copy()

    @property
    def body_mass(self) -> float:
        self._require()
        return self._body_mass

    @property
    def com(self) -> Array:
        """Body CoM (wheels excluded) in the axle frame."""
        self._require()
        return self._kept_copy("com", self._com_buffer)

    @property
    def J_com(self) -> Array:
        """Jacobian of :attr:`com` with respect to ``nu`` (``3 x n_min``)."""
        self._require()
        return self._kept_copy("J_com", self._J_com_buffer)

    @property
    def theta(self) -> float:
        """CoM pitch ``atan2(X_com, Z_com)`` in the axle frame; positive with the CoM ahead."""
        self._require()
        return self._theta

    @property
    def thetad(self) -> float:
        """``d theta / dt = J_theta @ nu`` (paper: ``cos(theta)/Z [cos, -sin] J_com qdot``)."""
        self._require()
        return self._thetad

    @property
    def J_theta(self) -> Array:
        """Row Jacobian of ``theta`` with respect to ``nu``."""
        self._require()
        return self._kept_copy("J_theta", self._J_theta_buffer)

    # ---------------------------------------------------------- derived
    def accelerations(self, ctrl: ArrayLike) -> Array:
        """Minimal accelerations ``nu_dot`` solving ``A nu_dot + h = B ctrl``."""
        self._require_dynamics()
        A, B, h = self._A_buffer, self._B_buffer, self._h_buffer
        return np.linalg.solve(A, B @ np.asarray(ctrl, dtype=float) - h)

    def full_accelerations(self, nu_dot: ArrayLike) -> Array:
        """MuJoCo's ``qacc`` for minimal accelerations: ``J_tf nu_dot + Jdot_tf nu``."""
        self._require()
        return self._J @ np.asarray(nu_dot, dtype=float) + self._Jdot_nu

    def body_inertia_about_axle(self) -> Array:
        """The body's (wheels excluded) inertia tensor about the axle midpoint, axle frame."""
        self._require()
        m, d = self.model, self.data
        return inertia_about_point(
            d.ximat,
            d.xipos,
            m.body_inertia,
            m.body_mass,
            self._body_ids,
            d.xpos[self.layout.base_body],
            np.ascontiguousarray(self.heading_rotation),
        )

    def wipm_parameters(self) -> WIPMParameters:
        """``lambda(q)`` at the current state (see :class:`WIPMParameters`); the reference
        for :meth:`wipm_values`, the controllers' path once per MPC step."""
        self._require_dynamics()  # the pitch inertia is an entry of A
        m, lay = self.model, self.layout
        w = lay.wheel_bodies[0]
        wheel_inertia = np.asarray(m.body_inertia[w])
        # inertia about the wheel's axle (y of the wheel body) and about a diameter
        flat = np.zeros(9)
        mujoco.mju_quat2Mat(flat, m.body_iquat[w])
        R = flat.reshape(3, 3)
        tensor = R @ np.diag(wheel_inertia) @ R.T
        com = self._com_buffer.copy()
        return WIPMParameters(
            body_mass=self._body_mass,
            com=com,
            com_distance=float(np.hypot(com[0], com[2])),
            theta=self._theta,
            thetad=self._thetad,
            pitch_inertia=float(self._A_buffer[lay.index_q1, lay.index_q1]),
            inertia_axle=self.body_inertia_about_axle(),
            wheel_mass=float(m.body_mass[w]),
            wheel_inertia=float(tensor[1, 1]),
            wheel_inertia_transverse=float(tensor[0, 0]),
            wheel_damping=float(m.dof_damping[lay.wheel_dof[0]]),
            wheel_radius=lay.wheel_radius,
            wheel_separation=lay.wheel_separation,
            gravity=float(-m.opt.gravity[2]),
        )

    def wipm_values(self) -> tuple[tuple[float, ...], Array]:
        """``lambda(q)`` as the WIPM takes it (paper section "Simplified Model";
        ``controllers.simplified.wipm.params_from_robot``) in one compiled call: the values of
        ``params_from_lambda(self.wipm_parameters())`` without the dataclass, the NumPy calls
        and the ~1 us views of each MuJoCo attribute read (Krang, through ``params_from_robot``:
        7 us against 67 us, medians in a tight loop).

        Returns ``(values, inertia_body)``: the scalars (floats) in :data:`WIPM_SCALARS`
        order, and the body's inertia about the axle midpoint in its CoM frame ``B`` (a new
        3x3 array). Masses, inertias, the wheel damping and gravity are read from the model at
        this call (as by :meth:`wipm_parameters`); the body mass, CoM and ``theta`` are the
        last update's. Needs an update (with or without dynamics).
        """
        self._require()
        lay = self.layout
        mujoco.mju_quat2Mat(self._wheel_frame, self._wheel_iquat)
        return kernels.wipm_values(
            self._wipm_table.rows,
            self.heading_rotation,
            self._com_buffer,
            self._body_mass,
            self._theta,
            lay.wheel_radius,
            lay.wheel_separation,
        )

    def wipm_inputs(self, out: Array | None = None) -> Array:
        """:meth:`wipm_state` and ``lambda(q)`` (:meth:`wipm_values`) as one vector, in one
        compiled call (``minimal_kernels.wipm_inputs_into``): the state, then ``lambda(q)``
        with one entry per field of ``controllers.simplified.wipm.WIPMParams`` in its order
        (``inertia_body`` row-major; ``minimal_kernels.WIPM_VECTOR_SIZES``). The same floats as
        those two methods (tested to the bit); what the MPC reads at each of its steps
        (``ModelPredictiveController.inputs_from``). Written into ``out`` (a float64 vector
        of that length, C-contiguous: ``ValueError`` otherwise) if given, else into a new
        vector; returned. Needs an update."""
        self._require()
        lay = self.layout
        size = (4 if lay.planar else 8) + kernels.WIPM_VECTOR_LENGTH
        if out is None:
            out = np.empty(size)
        elif (
            type(out) is not np.ndarray
            or out.shape != (size,)
            or out.dtype != np.float64
            or not out.flags.c_contiguous
            or not out.flags.writeable
        ):
            raise ValueError(
                f"wipm_inputs: out must be a writable, C-contiguous float64 vector of shape "
                f"({size},), got {getattr(out, 'dtype', type(out))} of shape {np.shape(out)}"
            )
        mujoco.mju_quat2Mat(self._wheel_frame, self._wheel_iquat)
        kernels.wipm_inputs_into(
            out,
            lay.planar,
            self._scalars,
            self._wipm_table.rows,
            self._com_buffer,
            lay.wheel_radius,
            lay.wheel_separation,
        )
        return out

    # ------------------------------------------------------- full state
    def full_state(
        self, q: ArrayLike, nu: ArrayLike, axle_xy: ArrayLike = (0.0, 0.0)
    ) -> tuple[Array, Array]:
        """MuJoCo ``(qpos, qvel)`` of the robot at minimal state ``(q, nu)`` with the wheels on
        the floor (axle at the wheel radius, level), and, in 3-D, the axle midpoint at
        ``axle_xy``. Wheel angles are split so that ``x`` is their odometry."""
        lay = self.layout
        q = np.asarray(q, dtype=float)
        nu = np.asarray(nu, dtype=float)
        n = lay.n_min
        if q.shape != (n,) or nu.shape != (n,):
            raise ValueError(f"expected q and nu of shape ({n},), got {q.shape}, {nu.shape}")
        axle = np.asarray(axle_xy, dtype=float)
        if axle.shape != (2,):
            raise ValueError(f"axle_xy must be (x, y), got {axle_xy!r}")
        qpos = np.zeros(lay.nq)
        qvel = np.zeros(lay.nv)
        idealised_state(
            q,
            nu,
            float(axle[0]),
            float(axle[1]),
            self._layout_ints,
            self._body_qpos,
            self._body_dof,
            lay.wheel_radius,
            lay.wheel_separation,
            qpos,
            qvel,
        )
        return qpos, qvel


def transform_pattern(J_constant: Array, layout: RobotLayout) -> NDArray[np.int64]:
    """``J_tf``'s nonzero pattern, ``(2, nnz)`` rows and columns sorted by column: its constant
    entries (``J_constant``, as ``RobotModel`` sets them) and, in 3-D, the four entries
    ``minimal_state`` writes at each state (the free joint's linear x, y rows in column
    ``x``; its angular x, z rows in column ``psi``)."""
    mask = J_constant != 0.0
    if not layout.planar:
        for row, column in kernels.FREE_JOINT_TF_ENTRIES:
            mask[layout.root_dof + row, column] = True
    rows, columns = np.nonzero(mask.T)[::-1]
    return np.array([rows, columns], dtype=np.int64)


def _read_only(array: _ArrayT) -> _ArrayT:
    array.flags.writeable = False
    return array
