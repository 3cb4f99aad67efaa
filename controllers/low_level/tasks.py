"""Low-level tasks of the whole-body QP (paper section "Optimization Based Control").

Each task is a small object (mink's style): ``jacobian(robot)`` over the minimal velocities
``nu`` and ``reference_acceleration(robot)``, the PD law of the paper

    xdd* = xdd_d - Kp (x - x_d) - Kv (xd - xd_d)

written once, as ``pd_acceleration`` (``controllers.low_level.compiled_tasks``: the compiled task
rows call the same function), which :class:`PDTask`, the base of every task here, applies to
the task's ``error`` and ``rate_error``: a task of a new kind gives those, its Jacobian, its
weights and its ``Jdot nu``, and nothing else.

The QP (``controllers.low_level.task_qp``) turns them into rows ``w J E qdd = w (xdd* - Jdot nu - J
e)`` (``nu_dot = E qdd + e`` from the isolated dynamics), with ``Jdot nu`` from each task's
``jdot_nu(probe)``: exact, from the drift accelerations of ``controllers.low_level.motion_probe``
(the QP refuses a task without it, by name). Frames:
end-effector targets live in the axle frame (origin at the axle midpoint, x along the heading, z up;
docs/DESIGN.md §4, docs/ERRATA.md §5).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import mujoco
import numpy as np
from numpy.typing import NDArray

from controllers.low_level.compiled_tasks import pd_acceleration
from controllers.low_level.motion_probe import MotionProbe
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]


def _scalar_slot(index: Any, value: Any) -> bool:
    """Whether ``value`` is stored as a scalar at ``array[index]`` (the attribute keeps the
    value) rather than as an array whose attribute becomes the stack's view: an int index,
    or a scalar spread over a slice of rows (a frame task's one weight)."""
    return isinstance(index, int) or (index is not None and np.ndim(value) == 0)


class StoredParameters:
    """Where a task's gains, targets and weights live once a compiled task stack holds them.

    ``controllers.low_level.task_stack.CompiledTaskStack`` keeps every task's parameters in
    its own arrays, which its compiled call reads in place: it *stores* a task's parameters
    there once (:meth:`store_parameters`), instead of copying them from the object every
    step. From then on the stack's arrays are the parameters' one source, and the object
    stays the way to change them:

    * an assigned scalar (``task.kp = 3.0``, ``task.theta_d = ...``, ``task.weight = ...``)
      is written into the stack's array too;
    * an array parameter (a ``target``, ``joint_weights``, a frame task's per-row
      ``weight``) *is* a view on the stack's array: an assignment of the same shape copies
      the new values into it (``task.target = R``), and a change in place
      (``task.target[0] += 0.1``) is seen as well. So an array read from the task before
      an assignment (``old = task.target``) shows the new values too: copy it to keep it.
      An assignment of another shape leaves the stack's arrays: the stack stores the task
      again before its next call (a value that does not broadcast to the parameter's shape
      is refused there, naming the task and the parameter), or a new stack is built when
      the task's structure changed with it (a posture task's columns).

    Any other assignment (a frame task's ``site``, a posture task's ``columns``, a ``name``)
    counts as a store event, so that a stack looks at its tasks' structure again before its
    next call (a posture task's columns changed in place, which is no assignment, are compared
    by their bytes every step).

    A task owns its arrays: an array given to its constructor (or by
    ``dataclasses.replace``) is copied, and a copy or a pickle of a task holds copies of its
    arrays and no stack's. A task taken by a second stack is stored there (the first stack
    takes it back before its next call).
    """

    _stored_slots: dict[str, tuple[Array, Any]] | None = None  # set by store_parameters
    _stored_by: object | None = None
    #: how many times any task was stored, left its stack's arrays or had an attribute the
    #: stack does not hold assigned (class-wide; ``DisturbanceRejectingTask`` counts its
    #: assignments here too): a stack that saw this count unchanged since it last checked its
    #: tasks owns them all still, and their structure is the one it checked
    store_events: ClassVar[int] = 0

    def __post_init__(self) -> None:
        state = self.__dict__
        for name, value in state.items():
            if isinstance(value, np.ndarray):
                state[name] = value.copy()

    if not TYPE_CHECKING:  # mypy would accept any attribute name with __setattr__ defined

        def __setattr__(self, name: str, value: Any) -> None:
            slots = self._stored_slots
            slot = None if slots is None else slots.get(name)
            if slot is None:
                # not held by a stack's arrays: maybe the task's structure (a site, ...)
                StoredParameters.store_events += 1
            else:
                array, index = slot
                if _scalar_slot(index, value):
                    array[index] = value  # a scalar: the attribute stays the value
                else:
                    view = array if index is None else array[index]
                    if np.shape(value) == view.shape:
                        view[...] = value
                        return  # the attribute is the view already
                    # another shape: the task leaves the stack's arrays; the stack
                    # stores it again before its next call (and refuses a shape it
                    # cannot hold), or is built anew if the task's structure changed
                    state = self.__dict__
                    state["_stored_slots"] = state["_stored_by"] = None
                    StoredParameters.store_events += 1
            object.__setattr__(self, name, value)

    def store_parameters(self, owner: object, slots: dict[str, tuple[Array, Any]]) -> None:
        """Keep the parameters named in ``slots`` in ``owner``'s arrays: ``(array, index)``
        for a scalar (``array[index]``; a slice for a weight spread over several rows),
        ``(view, None)`` for an array parameter. An array-valued parameter then becomes the
        view (``array[index]`` or ``view``); its current values are written there first.
        ``ValueError`` naming the task and the parameter if one does not fit."""
        state = self.__dict__
        for name, (array, index) in slots.items():
            value = state[name]
            scalar = _scalar_slot(index, value)
            view = array if index is None or scalar else array[index]
            try:
                if scalar:
                    array[index] = value
                else:
                    view[...] = value  # broadcast as the Python path's arithmetic would
            except (ValueError, TypeError) as error:
                raise ValueError(
                    f"task {getattr(self, 'name', type(self).__name__)!r}: its {name} of "
                    f"shape {np.shape(value)} does not fit the compiled task stack's "
                    f"{np.shape(array[index] if index is not None else array)}"
                ) from error
            if not scalar:
                state[name] = view
        state["_stored_slots"] = slots
        state["_stored_by"] = owner
        StoredParameters.store_events += 1

    def stored_by(self) -> object | None:
        """The owner of the arrays that hold this task's parameters (None: the object)."""
        return self._stored_by

    def __getstate__(self) -> dict[str, Any]:
        return {
            name: value.copy() if isinstance(value, np.ndarray) else value
            for name, value in self.__dict__.items()
            if name not in ("_stored_slots", "_stored_by")
        }


class PDTask(StoredParameters):
    """The base of every task: a subclass says what the task measures, the base how it is
    driven there.

    A subclass (a dataclass with the fields ``kp``, ``kv``, ``name`` and its weight) gives

    * ``jacobian(robot)``: ``J``, shape ``(m, n_min)``, the task's rows over ``nu``;
    * ``error(robot)``: ``x - x_d`` (``m``,);
    * ``rate_error(robot)``: ``xd - xd_d`` (``m``,), with ``xd = J nu``;
    * ``weights()``: one weight per row;
    * ``jdot_nu(probe)``: ``Jdot nu`` at the robot's state (``m``,);
    * ``feedforward()``, if the task tracks an acceleration: ``xdd_d`` (default 0).

    The base gives ``reference_acceleration(robot)``, the paper's PD law
    ``xdd* = xdd_d - Kp (x - x_d) - Kv (xd - xd_d)``, once, through :func:`pd_acceleration`,
    the function the compiled task rows call too. A task of a new kind runs on the task QP's
    Python path (docs/extending.md §1 has an example and how to make it compiled)."""

    if TYPE_CHECKING:  # the subclass's dataclass fields
        kp: float
        kv: float
        name: str

    def error(self, robot: RobotModel) -> Array:
        """``x - x_d`` at the robot's state."""
        raise NotImplementedError(f"{type(self).__name__} must give error(robot)")

    def rate_error(self, robot: RobotModel) -> Array:
        """``xd - xd_d`` at the robot's state (``xd = J nu``)."""
        raise NotImplementedError(f"{type(self).__name__} must give rate_error(robot)")

    def feedforward(self) -> float:
        """``xdd_d``, the acceleration the task tracks beside its PD terms (0: it holds a
        place)."""
        return 0.0

    def reference_acceleration(self, robot: RobotModel) -> Array:
        """The paper's PD law on this task's error and rate error (:func:`pd_acceleration`)."""
        return np.asarray(
            pd_acceleration(
                self.feedforward(), self.error(robot), self.rate_error(robot), self.kp, self.kv
            ),
            dtype=np.float64,
        )


class DesiredMotion(PDTask):
    """A task that tracks a scalar's desired value, rate and acceleration (``desired_names``),
    set together every control step by :meth:`set_desired`."""

    desired_names: ClassVar[tuple[str, str, str]]

    def set_desired(self, value: float, rate: float, acceleration: float) -> None:
        """Set the desired value, rate and acceleration (floats): the same as assigning the
        three attributes, written straight into a compiled stack's arrays when one holds
        them (``StoredParameters``), without three passes through ``__setattr__``."""
        state = self.__dict__
        slots = state.get("_stored_slots")
        first, second, third = self.desired_names
        if slots is None:
            state[first], state[second], state[third] = value, rate, acceleration
            return
        # per entry the stack's array first, then the attribute, as an assignment does (a
        # value the array refuses leaves both as they were); written out, not looped
        array, index = slots[first]
        array[index] = value
        state[first] = value
        array, index = slots[second]
        array[index] = rate
        state[second] = rate
        array, index = slots[third]
        array[index] = acceleration
        state[third] = acceleration


def _skew(v: Array) -> Array:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rotation_error(R: Array, R_target: Array) -> Array:
    """Rotation vector ``log(R R_target^T)`` (the rotation taking the target to ``R``)."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, (R @ R_target.T).reshape(-1))
    if quat[0] < 0:
        quat = -quat
    vector = np.zeros(3)
    mujoco.mju_quat2Vel(vector, quat, 1.0)
    return vector


def site_velocity_in_axle_frame(robot: RobotModel, site: int) -> tuple[Array, Array]:
    """``(Jp nu, Jr nu)`` of :func:`site_in_axle_frame`: the site's linear and angular
    velocity relative to the axle, in the axle frame. Memoised per robot state."""
    key = ("site_velocity_in_axle_frame", site)
    cached = robot.cache.get(key)
    if cached is None:
        _, _, Jp, Jr = site_in_axle_frame(robot, site)
        nu = robot.nu
        cached = robot.cache[key] = (Jp @ nu, Jr @ nu)
    return cached  # type: ignore[return-value]


def site_in_axle_frame(robot: RobotModel, site: int) -> tuple[Array, Array, Array, Array]:
    """Position, rotation, and Jacobians (linear, angular) over ``nu`` of a site in the axle
    frame (which turns with ``psi`` and does not pitch). Memoised per robot state."""
    key = ("site_in_axle_frame", site)
    cached = robot.cache.get(key)
    if cached is not None:
        return cached  # type: ignore[return-value]
    m, d, lay = robot.model, robot.data, robot.layout
    # [jacp; jacr] in one buffer: one product with J_tf for both
    jac = np.empty((6, m.nv))
    mujoco.mj_jacSite(m, d, jac[:3], jac[3:], site)
    origin = d.xpos[lay.base_body]
    origin_jac = robot.cache.get("origin_jacobian")
    if origin_jac is None:
        origin_jac = np.zeros((3, m.nv))
        mujoco.mj_jac(m, d, origin_jac, None, origin, lay.base_body)
        robot.cache["origin_jacobian"] = origin_jac
    jac[:3] -= origin_jac
    JJ = jac @ robot.J_tf
    if lay.index_psi is None:  # planar: the axle frame is the world's (Rh = I)
        rel = d.site_xpos[site] - origin
        Jp, Jr = JJ[:3], JJ[3:]
        R = d.site_xmat[site].reshape(3, 3).copy()
    else:
        Rt = robot.heading_rotation.T
        rel = Rt @ (d.site_xpos[site] - origin)
        Jp = Rt @ JJ[:3]
        Jr = Rt @ JJ[3:]
        ipsi = lay.index_psi
        x, y, _ = rel.tolist()
        Jp[0, ipsi] += y
        Jp[1, ipsi] -= x
        Jr[2, ipsi] -= 1.0
        R = Rt @ d.site_xmat[site].reshape(3, 3)
    robot.cache[key] = (rel, R, Jp, Jr)
    return rel, R, Jp, Jr


@dataclass
class ThetaTask(DesiredMotion):
    """Track the CoM pitch ``theta`` (the MPC's prediction, its ``thdd`` as feed-forward).
    Gains: the authors' COMAngleControl mode, KpCOM 50, KvCOM 100, weight 10."""

    weight: float = 10.0
    kp: float = 50.0
    kv: float = 100.0
    theta_d: float = 0.0
    thetad_d: float = 0.0
    thdd_d: float = 0.0
    name: str = "theta"

    desired_names: ClassVar[tuple[str, str, str]] = ("theta_d", "thetad_d", "thdd_d")

    def jacobian(self, robot: RobotModel) -> Array:
        return robot.J_theta[None, :]

    def error(self, robot: RobotModel) -> Array:
        return np.array([robot.theta - self.theta_d])

    def rate_error(self, robot: RobotModel) -> Array:
        return np.array([robot.thetad - self.thetad_d])

    def feedforward(self) -> float:
        return self.thdd_d

    def weights(self) -> Array:
        return np.array([self.weight])

    def jdot_nu(self, probe: MotionProbe) -> Array:
        """``d/dt (J_theta nu)`` at fixed ``nu``: with ``c`` the CoM in the axle frame and
        ``D = X^2 + Z^2``, ``(Z c''_x - X c''_z) / D - 2 thetad (X c'_x + Z c'_z) / D``."""
        c, c_d, c_dd = probe.relative_drift(*probe.com_motion())
        X, Z = c[0], c[2]
        D = X * X + Z * Z
        if D <= 1e-18:
            return np.zeros(1)
        thetad = (Z * c_d[0] - X * c_d[2]) / D
        return np.array(
            [(Z * c_dd[0] - X * c_dd[2]) / D - 2.0 * thetad * (X * c_d[0] + Z * c_d[2]) / D]
        )


@dataclass
class SpinTask(DesiredMotion):
    """Track the heading ``psi`` of the MPC's prediction (3-D)."""

    weight: float = 10.0
    kp: float = 50.0
    kv: float = 20.0
    psi_d: float = 0.0
    psid_d: float = 0.0
    psidd_d: float = 0.0
    name: str = "spin"

    desired_names: ClassVar[tuple[str, str, str]] = ("psi_d", "psid_d", "psidd_d")

    def jacobian(self, robot: RobotModel) -> Array:
        row = np.zeros((1, robot.layout.n_min))
        row[0, robot.layout.index_psi] = 1.0
        return row

    def error(self, robot: RobotModel) -> Array:
        return np.array([robot.psi - self.psi_d])

    def rate_error(self, robot: RobotModel) -> Array:
        return np.array([robot.nu[robot.layout.index_psi] - self.psid_d])

    def feedforward(self) -> float:
        return self.psidd_d

    def weights(self) -> Array:
        return np.array([self.weight])

    def jdot_nu(self, probe: MotionProbe) -> Array:
        return np.zeros(1)  # J is constant


@dataclass
class FramePositionTask(PDTask):
    """Hold a site's position in the axle frame (authors: KpEE 750, KvEE 250)."""

    site: int
    target: Array
    weight: float = 1.0
    kp: float = 750.0
    kv: float = 250.0
    name: str = "ee_position"

    def jacobian(self, robot: RobotModel) -> Array:
        return site_in_axle_frame(robot, self.site)[2]

    def error(self, robot: RobotModel) -> Array:
        return site_in_axle_frame(robot, self.site)[0] - self.target

    def velocity(self, robot: RobotModel) -> Array:
        """``J nu``: the site's velocity relative to the axle, in the axle frame."""
        return site_velocity_in_axle_frame(robot, self.site)[0]

    def rate_error(self, robot: RobotModel) -> Array:
        return self.velocity(robot)  # the target is held still

    def weights(self) -> Array:
        return np.full(3, self.weight)

    def jdot_nu(self, probe: MotionProbe) -> Array:
        """The site's drift acceleration relative to the axle, in the axle frame."""
        position, velocity, acceleration, _, _ = probe.site_motion(self.site)
        return np.array(probe.relative_drift(position, velocity, acceleration)[2])


@dataclass
class FrameOrientationTask(PDTask):
    """Hold a site's orientation in the axle frame (authors: KpOr 150, KvOr 50, weight 10).
    ``target`` may be changed every step (the waiter's tray)."""

    site: int
    target: Array
    weight: float = 10.0
    kp: float = 150.0
    kv: float = 50.0
    name: str = "ee_orientation"

    def jacobian(self, robot: RobotModel) -> Array:
        return site_in_axle_frame(robot, self.site)[3]

    def error(self, robot: RobotModel) -> Array:
        return rotation_error(site_in_axle_frame(robot, self.site)[1], self.target)

    def velocity(self, robot: RobotModel) -> Array:
        """``J nu``: the site's angular velocity relative to the axle frame, in it."""
        return site_velocity_in_axle_frame(robot, self.site)[1]

    def rate_error(self, robot: RobotModel) -> Array:
        return self.velocity(robot)  # the target is held still

    def weights(self) -> Array:
        return np.full(3, self.weight)

    def jdot_nu(self, probe: MotionProbe) -> Array:
        """``d/dt (Rh^T Omega - psid e_z) = Rh^T Omega' - omega x Rh^T Omega`` at fixed ``nu``
        (``Omega`` the site's angular velocity in world, ``omega = psid e_z``)."""
        _, _, _, omega, omega_drift = probe.site_motion(self.site)
        u = probe.to_axle(omega)
        a = probe.to_axle(omega_drift)
        w = probe.psid
        return np.array([a[0] + w * u[1], a[1] - w * u[0], a[2]])


@dataclass
class PostureTask(PDTask):
    """Regularise the body joints toward a posture (authors: KpPose 10, KvPose 20)."""

    target: Array
    joint_weights: Array
    kp: float = 10.0
    kv: float = 20.0
    name: str = "posture"
    columns: NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, dtype=int))

    def jacobian(self, robot: RobotModel) -> Array:
        rows = np.zeros((len(self.columns), robot.layout.n_min))
        rows[np.arange(len(self.columns)), self.columns] = 1.0
        return rows

    def error(self, robot: RobotModel) -> Array:
        return robot.q[self.columns] - self.target

    def rate_error(self, robot: RobotModel) -> Array:
        return robot.nu[self.columns]  # the posture is held still

    def weights(self) -> Array:
        return self.joint_weights

    def jdot_nu(self, probe: MotionProbe) -> Array:
        return np.zeros(len(self.columns))  # J is constant


Task = ThetaTask | SpinTask | FramePositionTask | FrameOrientationTask | PostureTask
