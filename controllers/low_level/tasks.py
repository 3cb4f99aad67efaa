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

from controllers.low_level import compiled_tasks as ct
from controllers.low_level.compiled_tasks import pd_acceleration
from controllers.low_level.motion_probe import MotionProbe
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]


class PDTask:
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
    readable path; to run it compiled, its class names its kind's compiled rows function
    (``compiled_kind``, ``controllers.low_level.compiled_tasks``) and gives ``parameters()``,
    the numbers that function reads, in its order (docs/extending.md §1). The task QP copies
    them from the object at every step: assign to a task's attributes as to any object's."""

    #: the compiled kind of this class's tasks (``controllers.low_level.compiled_tasks``), or
    #: None: the task QP's readable path. Only a class that sets it itself runs compiled (a
    #: subclass may change the arithmetic)
    compiled_kind: ClassVar[int | None] = None

    if TYPE_CHECKING:  # the subclass's dataclass fields
        kp: float
        kv: float
        name: str

    def parameters(self) -> list[float]:
        """The numbers this task's compiled rows read (``compiled_kind``), in their order:
        copied into the one-call step's table at every step."""
        raise NotImplementedError(f"{type(self).__name__} has no compiled rows")

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
        """Set the desired value, rate and acceleration (floats) together."""
        state = self.__dict__
        first, second, third = self.desired_names
        state[first], state[second], state[third] = value, rate, acceleration

    def parameters(self) -> list[float]:
        """``(kp, kv, desired value, rate, acceleration, weight)``."""
        state = self.__dict__
        first, second, third = self.desired_names
        return [
            state["kp"],
            state["kv"],
            state[first],
            state[second],
            state[third],
            state["weight"],
        ]


def _three(task: Any) -> list[float] | tuple[float, float, float]:
    """A three-row task's weights: one number for all (the common case, first), or three."""
    weight = task.weight
    if type(weight) is float:
        return weight, weight, weight
    return floats(weight, 3, task, "weight")


def floats(values: Any, count: int, task: Any, what: str) -> list[float]:
    """``values`` as ``count`` floats (row-major): an array of that many numbers, or one
    number for all (``ValueError`` naming the task and ``what`` otherwise). A task's
    ``parameters()`` give theirs so, at every step: an array's ``tolist`` first, the cheap
    case."""
    if type(values) is np.ndarray and values.size == count:
        return (values if values.ndim == 1 else values.ravel()).tolist()  # type: ignore[no-any-return]
    if type(values) is float:
        return [values] * count
    array = np.asarray(values, dtype=float)
    if array.size == count or array.size == 1:
        return array.ravel().tolist() * (count if array.size == 1 and count != 1 else 1)  # type: ignore[no-any-return]
    raise ValueError(
        f"task {getattr(task, 'name', type(task).__name__)!r}: {what} of shape "
        f"{np.shape(values)} for {count} rows (one per row, or one for all)"
    )


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
    if cached is None:
        m, d = robot.model, robot.data
        # [jacp; jacr] in one buffer: one product with J_tf for both
        jac = np.empty((6, m.nv))
        mujoco.mj_jacSite(m, d, jac[:3], jac[3:], site)
        cached = robot.cache[key] = _in_axle_frame(robot, jac, d.site_xpos[site], d.site_xmat[site])
    return cached  # type: ignore[return-value]


def body_point_in_axle_frame(
    robot: RobotModel, body: int, offset: Any = (0.0, 0.0, 0.0)
) -> tuple[Array, Array, Array, Array]:
    """:func:`site_in_axle_frame` for a point fixed on a body, ``offset`` in the body's frame
    (its origin by default): its position, the body's rotation, and the point's Jacobians
    (linear, angular) over ``nu``, in the axle frame. Memoised per robot state."""
    offset = np.asarray(offset, dtype=float)
    if offset.shape != (3,) or not 0 <= body < robot.model.nbody:
        raise ValueError(f"a body id and a 3-vector offset, got {body!r} and {offset.tolist()}")
    key = ("body_point_in_axle_frame", body, *offset.tolist())
    cached = robot.cache.get(key)
    if cached is None:
        m, d = robot.model, robot.data
        point = d.xpos[body] + d.xmat[body].reshape(3, 3) @ offset
        jac = np.empty((6, m.nv))
        mujoco.mj_jac(m, d, jac[:3], jac[3:], point, body)
        cached = robot.cache[key] = _in_axle_frame(robot, jac, point, d.xmat[body])
    return cached  # type: ignore[return-value]


def _in_axle_frame(
    robot: RobotModel, jac: Array, position: Array, rotation: Array
) -> tuple[Array, Array, Array, Array]:
    """A world point's (``position``, its world ``[jacp; jacr]`` over MuJoCo's dofs in
    ``jac``, overwritten) and a frame's (``rotation``, 9 entries row-major) position, rotation
    and Jacobians over ``nu`` in the axle frame."""
    m, d, lay = robot.model, robot.data, robot.layout
    origin = d.xpos[lay.base_body]
    origin_jac = robot.cache.get("origin_jacobian")
    if origin_jac is None:
        origin_jac = np.zeros((3, m.nv))
        mujoco.mj_jac(m, d, origin_jac, None, origin, lay.base_body)
        robot.cache["origin_jacobian"] = origin_jac
    jac[:3] -= origin_jac
    JJ = jac @ robot.J_tf
    if lay.index_psi is None:  # planar: the axle frame is the world's (Rh = I)
        rel = position - origin
        Jp, Jr = JJ[:3], JJ[3:]
        R = rotation.reshape(3, 3).copy()
    else:
        Rt = robot.heading_rotation.T
        rel = Rt @ (position - origin)
        Jp = Rt @ JJ[:3]
        Jr = Rt @ JJ[3:]
        ipsi = lay.index_psi
        x, y, _ = rel.tolist()
        Jp[0, ipsi] += y
        Jp[1, ipsi] -= x
        Jr[2, ipsi] -= 1.0
        R = Rt @ rotation.reshape(3, 3)
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
    compiled_kind: ClassVar[int | None] = ct.THETA

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
    compiled_kind: ClassVar[int | None] = ct.SPIN

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

    compiled_kind: ClassVar[int | None] = ct.POSITION

    def parameters(self) -> list[float]:
        """``(kp, kv, target (3), weights (3))``."""
        return [self.kp, self.kv, *floats(self.target, 3, self, "target"), *_three(self)]

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

    compiled_kind: ClassVar[int | None] = ct.ORIENTATION

    def parameters(self) -> list[float]:
        """``(kp, kv, target (3 x 3, row-major), weights (3))``."""
        return [self.kp, self.kv, *floats(self.target, 9, self, "target"), *_three(self)]

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

    compiled_kind: ClassVar[int | None] = ct.POSTURE

    def parameters(self) -> list[float]:
        """``(kp, kv, targets, weights)``, one target and one weight per column."""
        count = len(self.columns)
        return [
            self.kp,
            self.kv,
            *floats(self.target, count, self, "targets"),
            *floats(self.joint_weights, count, self, "joint weights"),
        ]

    def jacobian(self, robot: RobotModel) -> Array:
        rows = np.zeros((len(self.columns), robot.layout.n_min))
        rows[np.arange(len(self.columns)), self.columns] = 1.0
        return rows

    def error(self, robot: RobotModel) -> Array:
        return robot.q[self.columns] - self.target

    def rate_error(self, robot: RobotModel) -> Array:
        return robot.nu[self.columns]  # the posture is held still

    def weights(self) -> Array:
        return np.array(floats(self.joint_weights, len(self.columns), self, "joint weights"))

    def jdot_nu(self, probe: MotionProbe) -> Array:
        return np.zeros(len(self.columns))  # J is constant


Task = ThetaTask | SpinTask | FramePositionTask | FrameOrientationTask | PostureTask
