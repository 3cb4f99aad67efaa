"""The paper's hierarchical whole-body controller (``unified`` / ``unified-waiter``).

High level (``controllers.high_level.receding_horizon``): the offline DDP plan at reset, MPC every
10 ms on the WIPM with ``lambda(q)`` from the current state, giving ``thdd_ref`` (and the spin).
Low level, every control step (1 ms): the task QP on the isolated manipulator dynamics (eq.
``iso3``; ``controllers.low_level.task_qp``) with the tasks of the paper's results section:
``theta`` (toward the MPC's predicted ``theta``, ``thetad``, interpolated inside the 10 ms, with
its ``thdd`` as feed-forward), the end effector's position and orientation in the axle frame at
their reset values, posture regularisation, and in 3-D the heading from the MPC (a heading task
toward its predicted ``psi``, or, as the paper does, its ``tau_0`` applied: ``spin_source``; the
preset ``HierarchicalConfig.paper()`` is the authors' configuration). Torques reach the wheels
through the tested ``(tau_0, tau_1) -> (tau_L, tau_R)`` map. The whole body, wheels included,
balances and drives while the hand holds its task.

Tray modes (docs/DESIGN.md §4): ``level`` (the paper: the end effector keeps its reset orientation
in the axle frame, so a level tray stays level) and ``specific_force`` (beyond the paper,
docs/ERRATA.md §5: the tray's up-normal follows ``a_ref - g``, ``g = (0, 0, -9.81)``, ``a_ref`` the
horizontal acceleration of the axle the MPC predicts (centripetal part included), the tilt bounded
by ``max_tray_tilt_deg``: a waiter's tray, whose cup feels no tangential force in steady
acceleration).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import mujoco
import numpy as np
from numpy.typing import NDArray

from controllers.high_level.planning import Plan, PlanConfig
from controllers.high_level.receding_horizon import HighLevel, HighLevelConfig
from controllers.high_level.tray_reference import tilt_toward
from controllers.low_level.disturbance_tasks import DisturbanceRejectingTask, ObserverSettings
from controllers.low_level.priority_qp import PRIORITIES, Priority, PriorityQP, PriorityStep
from controllers.low_level.task_qp import QPSettings, TaskQP
from controllers.low_level.tasks import (
    FrameOrientationTask,
    FramePositionTask,
    PostureTask,
    SpinTask,
    Task,
    ThetaTask,
    site_in_axle_frame,
)
from controllers.policy import ModelChoice, PolicyBase, TaskInfo, plan_counters
from wip_gym.robot_model import RobotModel
from wip_gym.wheel_torques import generalized_to_wheel_matrix

Array = NDArray[np.float64]
#: a user's task (or constraint) for the controller: made at every reset from its robot model
TaskFactory = Callable[[RobotModel], Any]


@dataclass(frozen=True)
class HierarchicalConfig:
    """Settings of the hierarchical controller; the authors' values (docs/AUTHORS_CONFIG.md §4.3).

    Attributes:
        model: ``nominal`` or ``oracle``.
        tray_mode: ``level`` (the paper) or ``specific_force`` (the waiter).
        max_tray_tilt_deg: bound of the waiter's tilt.
        tray_lead_s: the waiter tilts for the acceleration the MPC predicts this far ahead, to
            make up for the orientation task's lag (its PD settles in about 0.1 s).
        tray_window_s: the waiter's acceleration is averaged over this window of the MPC's
            prediction.
        theta_weight, theta_kp, theta_kv: theta task (authors' COMAngleControl: w 10, Kp 50,
            Kv 100). We weight it 100: balance comes first.
        spin_weight, spin_kp, spin_kv: heading task (3-D).
        spin_source: how the heading is driven in 3-D: ``heading_task`` (ours: a QP task toward
            the MPC's predicted ``psi``) or ``mpc_tau_0`` (the paper: the QP's own ``tau_0``
            is replaced by the MPC's ``tau_0``, the generalised force on ``psi`` of the WIPM,
            i.e. ``tau_R - tau_L = (2R/sep) tau_0``: the DDP model's convention with
            ``B = sep/(2R)``, docs/AUTHORS_CONFIG.md §4.5 and §2.4; the QP's torque limits do
            not see that replacement, the final clip counts what exceeds them).
        ee_position_weight, ee_kp, ee_kv: end-effector position (authors: W = diag(0, 1, 10)
            over (forward, lateral, up) in the axle frame, Kp 750, Kv 250); a number weights
            all three axes, a triple each axis.
        ee_orientation_weight, orientation_kp, orientation_kv: end-effector orientation
            (authors: 10, 150, 50).
        posture_weight, posture_kp, posture_kv: the body joints toward their reset values
            (authors: weights 0..10 per joint, Kp 10, Kv 20).
            ``posture_weight`` ``"authors"``: their per-joint weights (docs/AUTHORS_CONFIG.md
            §4.3: torso 1, waist 0, arm joints 1-4 10, 5-7 5), matched to our joints by name.
        speed_regularization_kv: the authors' speed regularisation (``-KvSpeedReg qd``,
            KvSpeedReg 10, weights base pitch 1, waist 10, torso 10, arms 1); None (default):
            off.
        hand_observer_bandwidth: ``w`` (rad/s) of the estimate of the unmodelled acceleration
            of the end-effector tasks (``controllers.low_level.disturbance_tasks``; not in the
            paper, whose nominal inverse dynamics let an unmodelled payload tip the tray); None
            turns it off. 50 rad/s: well above the slow pole of the authors' PD gains (about
            3 rad/s for both Kp 750 / Kv 250 and Kp 150 / Kv 50), under the 1 kHz step's
            Nyquist rate by a factor of 60.
        hand_observer_position_bound, hand_observer_orientation_bound: anti-windup clamps of
            that estimate (m/s^2, rad/s^2). With the README's 3 kg payload on ``planar7`` the
            estimate measured up to 47 rad/s^2 (orientation) and 8 m/s^2 (position), and a
            clamp of 15 (the authors' Kp times 2 cm or 0.1 rad) let the tray tip 32 deg: 100
            leaves a factor 2 over the largest measured need and still stops a runaway.
        extra_tasks: the user's own tasks, as factories: each is called at every reset with the
            controller's robot model (updated to the reset state: a factory may read its pose,
            as the paper's tasks do) and gives a task (``controllers.low_level.tasks``), added
            to the stack after the paper's. A task of a class without compiled rows makes the
            QP take its readable path (docs/extending.md §1).
        constraints: the user's own constraints of the task QP, as factories likewise
            (``controllers.low_level.constraints``).
        priority: ``weighted`` (the paper: one QP trading every task by its weight) or
            ``strict`` (balance, then the hands and heading, then posture, as lexicographic
            levels under the torque and joint limits; ``unified-upright`` puts its drive row
            and the hands' forward rows with the posture, ``UprightConfig.strict_posture_rows``;
            ``controllers.low_level.priority_qp``, docs/upright.md §4).
        high_level: plan and MPC settings. qp: QP settings.
    """

    model: ModelChoice = "nominal"
    tray_mode: Literal["level", "specific_force"] = "level"
    max_tray_tilt_deg: float = 20.0
    tray_lead_s: float = 0.1
    tray_window_s: float = 0.1
    theta_weight: float = 100.0
    theta_kp: float = 50.0
    theta_kv: float = 100.0
    spin_weight: float = 10.0
    spin_kp: float = 50.0
    spin_kv: float = 20.0
    spin_source: Literal["heading_task", "mpc_tau_0"] = "heading_task"
    ee_position_weight: float | tuple[float, float, float] = 10.0
    ee_kp: float = 750.0
    ee_kv: float = 250.0
    ee_orientation_weight: float = 10.0
    orientation_kp: float = 150.0
    orientation_kv: float = 50.0
    posture_weight: float | Literal["authors"] = 1.0
    posture_kp: float = 10.0
    posture_kv: float = 20.0
    speed_regularization_kv: float | None = None
    hand_observer_bandwidth: float | None = 50.0
    hand_observer_position_bound: float = 100.0
    hand_observer_orientation_bound: float = 100.0
    extra_tasks: tuple[TaskFactory, ...] = ()
    constraints: tuple[TaskFactory, ...] = ()
    priority: Priority = "weighted"
    high_level: HighLevelConfig = field(default_factory=HighLevelConfig)
    qp: QPSettings = field(default_factory=QPSettings)

    def __post_init__(self) -> None:
        for name in ("extra_tasks", "constraints"):
            factories = getattr(self, name)
            if not isinstance(factories, tuple) or not all(map(callable, factories)):
                raise ValueError(
                    f"{name} must be a tuple of factories, each called with the robot model at "
                    f"reset, got {factories!r}"
                )
        if self.priority not in PRIORITIES:
            raise ValueError(f"priority must be one of {PRIORITIES}, got {self.priority!r}")
        if self.tray_mode not in ("level", "specific_force"):
            raise ValueError(f"tray_mode must be level or specific_force, got {self.tray_mode!r}")
        if self.spin_source not in ("heading_task", "mpc_tau_0"):
            raise ValueError(
                f"spin_source must be heading_task or mpc_tau_0, got {self.spin_source!r}"
            )
        if isinstance(self.posture_weight, str) and self.posture_weight != "authors":
            raise ValueError(
                f"posture_weight must be a number or 'authors', got {self.posture_weight!r}"
            )
        horizon = self.high_level.mpc.horizon_s
        if not (0.0 <= self.tray_lead_s < horizon and self.tray_window_s >= 0.0):
            # a negative lead wrapped to the prediction's end; one at or past the horizon read
            # past it (or divided by a zero span)
            raise ValueError(
                f"tray_lead_s must be in [0, the MPC horizon {horizon} s) and tray_window_s "
                f">= 0, got {self.tray_lead_s!r} and {self.tray_window_s!r}"
            )
        weights = np.asarray(self.ee_position_weight, dtype=float)
        if weights.shape not in ((), (3,)) or not np.all(weights >= 0):
            raise ValueError(
                f"ee_position_weight must be a number or 3 numbers >= 0, got "
                f"{self.ee_position_weight!r}"
            )

    @classmethod
    def paper(cls, tray_mode: Literal["level", "specific_force"] = "level") -> HierarchicalConfig:
        """The authors' low level (docs/AUTHORS_CONFIG.md §4.3, §4.5) on the paper's plan:
        position task diag(0, 1, 10) over (forward, lateral, up) in the axle frame, theta task
        weight 10 (Kp 50, Kv 100), orientation 10 (Kp 150, Kv 50), their posture (KpPose 10,
        KvPose 20, per-joint weights) and speed regularisation (KvSpeedReg 10), no hand
        observer, in 3-D the MPC's ``tau_0`` applied instead of our heading task, and the
        plan of ``PlanConfig.paper()``. Our MPC and QP settings are kept."""
        return cls(
            tray_mode=tray_mode,
            theta_weight=10.0,
            theta_kp=50.0,
            theta_kv=100.0,
            spin_source="mpc_tau_0",
            ee_position_weight=(0.0, 1.0, 10.0),
            ee_kp=750.0,
            ee_kv=250.0,
            ee_orientation_weight=10.0,
            orientation_kp=150.0,
            orientation_kv=50.0,
            posture_weight="authors",
            posture_kp=10.0,
            posture_kv=20.0,
            speed_regularization_kv=10.0,
            hand_observer_bandwidth=None,
            high_level=HighLevelConfig(plan=PlanConfig.paper()),
        )


# The authors' regularisation weights (docs/AUTHORS_CONFIG.md §4.3), by the kind of joint:
# (posture weight, speed-regularisation weight). Arm joints by their index along the arm (1-7).
AUTHORS_JOINT_WEIGHTS = {"base": (0.0, 1.0), "waist": (0.0, 10.0), "torso": (1.0, 10.0),
                         "kinect": (0.0, 1.0), 1: (10.0, 1.0), 2: (10.0, 1.0), 3: (10.0, 1.0),
                         4: (10.0, 1.0), 5: (5.0, 1.0), 6: (5.0, 1.0), 7: (5.0, 1.0)}  # fmt: skip
# our joint names -> the authors' kind: Krang's own names; the planar arm's shoulder, elbow and
# wrist pitch are Krang's bending joints 2, 4, 6
_JOINT_KIND: dict[str, str | int] = {"waist": "waist", "spine": "waist", "torso": "torso",
                                     "kinect": "kinect", "shoulder": 2, "elbow": 4,
                                     "wrist": 6}  # fmt: skip


def authors_joint_weights(robot: RobotModel) -> tuple[Array, Array]:
    """Posture and speed-regularisation weights of the authors for the body joints of
    ``robot`` (``layout.body_dof`` order; the base pitch excluded). ``ValueError`` for a joint
    the table cannot place."""
    m = robot.model
    posture, speed = [], []
    for dof in robot.layout.body_dof:
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, m.dof_jntid[dof]) or ""
        kind = _JOINT_KIND.get(name)
        if kind is None and name[:-1].endswith("_j") and name[-1].isdigit():
            kind = int(name[-1])
        if kind is None:
            raise ValueError(
                f"no authors' regularisation weight for joint {name!r}; known: "
                f"{sorted(map(str, _JOINT_KIND))} and <arm>_j1..7"
            )
        p, v = AUTHORS_JOINT_WEIGHTS[kind]
        posture.append(p)
        speed.append(v)
    return np.array(posture), np.array(speed)


# the per-step diagnostics, in the order __call__ records them (DiagnosticsRecorder.record_row);
# the first two are stored as the robot update's scalars and the MPC index, and made into the
# WIPM state and the plan's state when the diagnostics are read (cheaper per step)
_SIGNALS = (
    "t",
    "wipm_state",
    "wipm_reference",
    "theta_d",
    "thetad_d",
    "thdd_ref",
    "tau_0",
    "torque",
    "clip_excess",
    "qp_solved",
    "qp_iterations",
    "qp_failures",
    "mpc_rejected",
    "theta_error",
    "mpc_time",
    "qp_time",
    "compute_time",
)


class HierarchicalController(PolicyBase):
    """The paper's controller (see the module docstring)."""

    config_class = HierarchicalConfig

    def __init__(self, robot: RobotModel, task: TaskInfo, config: HierarchicalConfig) -> None:
        super().__init__(robot, task, config)
        self.high_level = HighLevel(config.high_level, task.control_dt)
        self.qp = TaskQP(robot, task.torque_low, task.torque_high, config.qp)
        self.priority_qp = PriorityQP(self.qp)
        m = robot.model
        self._sites = [
            mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name) for name in ("ee", "ee_right")
        ]
        self._sites = [s for s in self._sites if s >= 0]
        self.plan: Plan | None = None
        self._fallbacks = 0
        lay = robot.layout
        self._mpc_tau_0 = not lay.planar and config.spin_source == "mpc_tau_0"
        if self._mpc_tau_0:
            self._wheels_of_tau_0 = generalized_to_wheel_matrix(
                lay.wheel_radius, lay.wheel_separation
            )[:, 0]

    @property
    def name(self) -> str:
        return "unified" if self.config.tray_mode == "level" else "unified-waiter"

    # ----------------------------------------------------------------- reset
    def reset(self, observation: dict[str, Array], info: dict[str, Any]) -> None:
        robot, cfg, lay = self.robot, self.config, self.robot.layout
        robot.update(observation["qpos"], observation["qvel"])
        self.begin_episode()
        self._fallbacks = 0
        self.plan = self.high_level.reset(robot, self.task.goal, self.task.cup_friction)
        self.theta_task = ThetaTask(cfg.theta_weight, cfg.theta_kp, cfg.theta_kv)
        tasks: list[Task] = [self.theta_task]
        self.spin_task: SpinTask | None = None
        if not lay.planar and not self._mpc_tau_0:
            self.spin_task = SpinTask(cfg.spin_weight, cfg.spin_kp, cfg.spin_kv, psi_d=robot.psi)
            tasks.append(self.spin_task)
        self.orientation_tasks: list[FrameOrientationTask] = []
        self._orientation_reset: list[Array] = []
        # the waiter's tray target, made once per MPC solution (_set_references)
        self._tray_target: tuple[object, Array] | None = None
        for site in self._sites:
            position, rotation, _, _ = site_in_axle_frame(robot, site)
            position_task = FramePositionTask(
                site,
                position,
                cfg.ee_position_weight,
                cfg.ee_kp,
                cfg.ee_kv,
                name=f"position_{site}",
            )
            orientation = FrameOrientationTask(
                site,
                rotation.copy(),
                cfg.ee_orientation_weight,
                cfg.orientation_kp,
                cfg.orientation_kv,
                name=f"orientation_{site}",
            )
            tasks += [
                self._observed(position_task, cfg.hand_observer_position_bound),
                self._observed(orientation, cfg.hand_observer_orientation_bound),
            ]
            self.orientation_tasks.append(orientation)
            self._orientation_reset.append(rotation.copy())
        columns = np.arange(lay.index_q1 + 1, lay.n_min)
        if cfg.posture_weight == "authors" or cfg.speed_regularization_kv is not None:
            posture_weights, speed_weights = authors_joint_weights(robot)
        if cfg.posture_weight != "authors":
            posture_weights = np.full(len(columns), float(cfg.posture_weight))
        # the two ignores below: tasks.py annotates PostureTask.columns as float64, they are
        # indices (an int array); to go when that annotation is fixed
        if len(columns):
            tasks.append(
                PostureTask(
                    robot.q[columns].copy(),
                    posture_weights,
                    cfg.posture_kp,
                    cfg.posture_kv,
                    columns=columns,
                )
            )
        if cfg.speed_regularization_kv is not None:
            # -Kv qd on the base pitch and every body joint: a posture task without stiffness
            base_pitch = AUTHORS_JOINT_WEIGHTS["base"][1]
            speed_columns = np.arange(lay.index_q1, lay.n_min)
            tasks.append(
                PostureTask(
                    np.zeros(len(speed_columns)),
                    np.concatenate([[base_pitch], speed_weights]),
                    0.0,
                    cfg.speed_regularization_kv,
                    name="speed_regularization",
                    columns=speed_columns,
                )
            )
        self.tasks = tasks + [make(robot) for make in cfg.extra_tasks]
        self.constraints = [make(robot) for make in cfg.constraints]
        self.qp.failures = 0
        # one QP now (creates and compiles the solver object), from the current state
        self.theta_task.theta_d, self.theta_task.thetad_d = robot.theta, robot.thetad
        # None: eq. iso3 inside the QP's kernel
        first = self.qp.solve(robot, None, self.tasks, self.constraints)
        self._last_tau_0_qp = float(first.generalized[0])
        for task in self.tasks:
            if isinstance(task, DisturbanceRejectingTask):
                task.restart()  # the first control step sees this same state again

    def _observed(self, task: Task, bound: float) -> Any:
        """``task`` with the estimate of its unmodelled acceleration, if configured."""
        bandwidth = self.config.hand_observer_bandwidth
        if bandwidth is None:
            return task
        return DisturbanceRejectingTask(
            task, ObserverSettings(self.task.control_dt, bandwidth, bound)
        )

    def _set_references(self, robot: RobotModel) -> None:
        ref = self.high_level.reference(robot)
        self.theta_task.set_desired(ref.theta, ref.thetad, ref.thdd)
        if self.spin_task is not None:
            self.spin_task.set_desired(ref.psi, ref.psid, ref.psidd)
        if self.config.tray_mode == "specific_force" and self.orientation_tasks:
            # the tilt depends on the MPC solution only: made when a new one is in use
            solution = self.high_level.last_solution
            if self._tray_target is None or self._tray_target[0] is not solution:
                acceleration = self._predicted_acceleration(robot)
                tilt = tilt_toward(acceleration, self.config.max_tray_tilt_deg)
                self._tray_target = (solution, tilt @ self._orientation_reset[0])
            self.orientation_tasks[0].target = self._tray_target[1].copy()
        self._ref = ref

    def _predicted_acceleration(self, robot: RobotModel) -> Array:
        """The axle's horizontal acceleration (axle frame, ``(xdd, xd psid)``) that the current
        MPC solution predicts ``tray_lead_s`` ahead, averaged over ``tray_window_s`` (a
        velocity difference across the window: the raw 10 ms differences are noisy)."""
        states = self.high_level.last_solution.predicted_states
        dt = self.high_level.config.mpc.dt
        half = max(1, int(round(0.5 * self.config.tray_window_s / dt)))
        j = int(round(self.config.tray_lead_s / dt))
        lo, hi = max(j - half, 0), min(j + half, len(states) - 1)
        xdd = (states[hi, 3] - states[lo, 3]) / ((hi - lo) * dt)
        lateral = 0.0 if robot.layout.planar else states[j, 3] * states[j, 4]
        return np.array([xdd, lateral])

    # ------------------------------------------------------------------ step
    def __call__(self, observation: dict[str, Array]) -> Array:
        if self.plan is None:
            raise RuntimeError(f"{type(self).__name__}: reset() before the first step")
        start = time.perf_counter()
        robot = self.robot
        robot.update(observation["qpos"], observation["qvel"])
        tick = time.perf_counter()
        self._set_references(robot)
        mpc_time = time.perf_counter() - tick
        tick = time.perf_counter()
        solution = self._solve(robot).solution
        qp_time = time.perf_counter() - tick
        actuators = solution.actuators
        if not solution.solved:
            self._fallbacks += 1
        if self._mpc_tau_0:
            # the paper: the QP's tau_0 replaced by the MPC's (spin_source, config docstring)
            tau_0_qp = solution.generalized[0] if solution.solved else self._last_tau_0_qp
            self._last_tau_0_qp = tau_0_qp
            actuators = actuators.copy()
            wl, wr = self.robot.layout.wheel_actuators
            shift = self._wheels_of_tau_0 * (self._ref.tau_0 - tau_0_qp)
            actuators[wl] += shift[0]
            actuators[wr] += shift[1]
        action = self.finish(actuators)
        ref = self._ref
        self._recorder.record_row(
            _SIGNALS,
            (
                self._step * self.task.control_dt,
                robot.update_scalars(),  # -> wipm_state (diagnostics)
                ref.mpc_index,  # -> wipm_reference (diagnostics)
                ref.theta,
                ref.thetad,
                ref.thdd,
                ref.tau_0,
                action.copy(),
                self._clip.last_excess,
                solution.solved,
                solution.iterations,
                self.qp.failures,
                self.high_level.rejections,
                robot.theta - ref.theta,
                mpc_time,
                qp_time,
                time.perf_counter() - start,
            ),
        )
        self._step += 1
        return action

    def _solve(self, robot: RobotModel) -> PriorityStep:
        """This step's task QP (eq. iso3 from ``robot`` in the QP's kernel), by the
        configured priority."""
        return self.priority_qp.solve(robot, self.tasks, self.constraints, self.config.priority)

    @property
    def diagnostics(self) -> dict[str, Array]:
        """Per-step ``t``, ``wipm_state``, ``wipm_reference`` (plan at the MPC index),
        ``theta_d``, ``thetad_d``, ``thdd_ref``, ``tau_0`` (MPC), ``torque`` (every actuator,
        applied), ``clip_excess`` (N m by which the action exceeded its bounds),
        ``qp_solved``, ``qp_iterations``, ``qp_failures`` and ``mpc_rejected`` (running
        counts), ``theta_error``, and the timings ``mpc_time``, ``qp_time``,
        ``compute_time``."""
        arrays = self._recorder.as_arrays()
        if "wipm_state" in arrays:
            plan = self.plan
            if plan is None:  # rows are recorded only after reset made one
                raise RuntimeError("the diagnostics' plan is gone (policy.plan was set to None)")
            arrays["wipm_state"] = self.robot.wipm_states(arrays["wipm_state"])
            arrays["wipm_reference"] = plan.states_at(arrays["wipm_reference"])
        return arrays

    def controller_counters(self) -> dict[str, float]:
        """``qp_fallbacks`` (steps that applied the previous step's torques because the QP was
        not solved), ``qp_failures`` (QPs ProxQP did not solve; equal to the fallbacks, the
        QP's own count), ``mpc_rejections``, ``plan_violations``, ``plan_converged``."""
        counters = {"qp_fallbacks": float(self._fallbacks), "qp_failures": float(self.qp.failures)}
        if self.high_level.mpc is not None:
            counters["mpc_rejections"] = float(self.high_level.rejections)
        if self.plan is not None:
            counters.update(plan_counters(self.plan))
        return counters
