"""The paper's hierarchical whole-body controller (``unified`` / ``unified-waiter``).

High level (``controllers.high_level``): the offline DDP plan at reset, MPC every 10 ms on the
WIPM with ``lambda(q)`` from the current state, giving ``thdd_ref`` (and the spin). Low level,
every control step (1 ms): the task QP on the isolated manipulator dynamics (eq. ``iso3``;
``controllers.task_qp``) with the tasks of the paper's results section: ``theta`` (toward the
MPC's predicted ``theta``, ``thetad``, interpolated inside the 10 ms, with its ``thdd`` as
feed-forward), the end effector's position and orientation in the axle frame at their reset
values, posture regularisation, and in 3-D the heading from the MPC. Torques reach the wheels
through the tested ``(tau_0, tau_1) -> (tau_L, tau_R)`` map. The whole body, wheels included,
balances and drives while the hand holds its task.

Tray modes (DESIGN 4): ``level`` (the paper: the end effector keeps its reset orientation in
the axle frame, so a level tray stays level) and ``specific_force`` (beyond the paper, ERRATA 5:
the tray's up-normal follows ``a_ref - g``, ``g = (0, 0, -9.81)``, ``a_ref`` the horizontal
acceleration of the axle the MPC predicts (centripetal part included), the tilt bounded by
``max_tray_tilt_deg``: a waiter's tray, whose cup feels no tangential force in steady
acceleration).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Literal

import gymnasium as gym
import mujoco
import numpy as np
from numpy.typing import NDArray

from controllers.disturbance_tasks import DisturbanceRejectingTask, ObserverSettings
from controllers.high_level import HighLevel, HighLevelConfig
from controllers.policy import DiagnosticsRecorder, ModelChoice, TaskInfo, make_robot, task_info
from controllers.task_qp import QPSettings, TaskQP
from controllers.tasks import (
    FrameOrientationTask,
    FramePositionTask,
    PostureTask,
    SpinTask,
    Task,
    ThetaTask,
    site_in_axle_frame,
)
from controllers.wipm_problem import wipm_state
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]
GRAVITY = 9.81


@dataclass(frozen=True)
class HierarchicalConfig:
    """Settings of the hierarchical controller; the authors' values (krang_facts 4.3).

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
        ee_position_weight, ee_kp, ee_kv: end-effector position (authors: W up to 10, Kp 750,
            Kv 250).
        ee_orientation_weight, orientation_kp, orientation_kv: (authors: 10, 150, 50).
        posture_weight, posture_kp, posture_kv: (authors: weights 0..10 per joint, Kp 10, Kv 20).
        hand_observer_bandwidth: ``w`` (rad/s) of the estimate of the unmodelled acceleration
            of the end-effector tasks (``controllers.disturbance_tasks``; not in the paper,
            whose nominal inverse dynamics let an unmodelled payload tip the tray); None turns
            it off. 50 rad/s: well above the slow pole of the authors' PD gains (about
            3 rad/s for both Kp 750 / Kv 250 and Kp 150 / Kv 50), under the 1 kHz step's
            Nyquist rate by a factor of 60.
        hand_observer_position_bound, hand_observer_orientation_bound: anti-windup clamps of
            that estimate (m/s^2, rad/s^2). With the README's 3 kg payload on ``planar7`` the
            estimate measured up to 47 rad/s^2 (orientation) and 8 m/s^2 (position), and a
            clamp of 15 (the authors' Kp times 2 cm or 0.1 rad) let the tray tip 32 deg: 100
            leaves a factor 2 over the largest measured need and still stops a runaway.
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
    ee_position_weight: float = 10.0
    ee_kp: float = 750.0
    ee_kv: float = 250.0
    ee_orientation_weight: float = 10.0
    orientation_kp: float = 150.0
    orientation_kv: float = 50.0
    posture_weight: float = 1.0
    posture_kp: float = 10.0
    posture_kv: float = 20.0
    hand_observer_bandwidth: float | None = 50.0
    hand_observer_position_bound: float = 100.0
    hand_observer_orientation_bound: float = 100.0
    high_level: HighLevelConfig = field(default_factory=HighLevelConfig)
    qp: QPSettings = field(default_factory=QPSettings)


def tilt_toward(acceleration: Array, max_tilt_deg: float) -> Array:
    """Rotation (axle frame) taking ``e_z`` to the direction of ``a - g``, tilt bounded."""
    specific = np.array([acceleration[0], acceleration[1], GRAVITY])
    n = specific / np.linalg.norm(specific)
    axis = np.cross([0.0, 0.0, 1.0], n)
    s = np.linalg.norm(axis)
    angle = min(np.arctan2(s, n[2]), np.radians(max_tilt_deg))
    if s < 1e-12:
        return np.eye(3)
    quat = np.zeros(4)
    mujoco.mju_axisAngle2Quat(quat, axis / s, angle)
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, quat)
    return R.reshape(3, 3)


class HierarchicalController:
    """The paper's controller (see the module docstring)."""

    def __init__(self, robot: RobotModel, task: TaskInfo, config: HierarchicalConfig) -> None:
        if config.tray_mode not in ("level", "specific_force"):
            raise ValueError(f"tray_mode must be level or specific_force, got {config.tray_mode!r}")
        self.robot = robot
        self.task = task
        self.config = config
        self.high_level = HighLevel(config.high_level, task.control_dt)
        self.qp = TaskQP(robot, task.torque_low, task.torque_high, config.qp)
        self._recorder = DiagnosticsRecorder()
        m = robot.model
        self._sites = [
            mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name) for name in ("ee", "ee_right")
        ]
        self._sites = [s for s in self._sites if s >= 0]

    @property
    def name(self) -> str:
        return "unified" if self.config.tray_mode == "level" else "unified-waiter"

    @classmethod
    def for_env(cls, env: gym.Env, config: HierarchicalConfig | None = None
                ) -> HierarchicalController:  # fmt: skip
        config = config or HierarchicalConfig()
        return cls(make_robot(env, config.model), task_info(env, config.model), config)

    # ----------------------------------------------------------------- reset
    def reset(self, observation: dict[str, Array], info: dict[str, Any]) -> None:
        robot, cfg, lay = self.robot, self.config, self.robot.layout
        robot.update(observation["qpos"], observation["qvel"])
        self._recorder.clear()
        self._step = 0
        self.plan = self.high_level.reset(robot, self.task.goal, self.task.cup_friction)
        self.theta_task = ThetaTask(cfg.theta_weight, cfg.theta_kp, cfg.theta_kv)
        tasks: list[Task] = [self.theta_task]
        self.spin_task: SpinTask | None = None
        if not lay.planar:
            self.spin_task = SpinTask(cfg.spin_weight, cfg.spin_kp, cfg.spin_kv, psi_d=robot.psi)
            tasks.append(self.spin_task)
        self.orientation_tasks: list[FrameOrientationTask] = []
        self._orientation_reset: list[Array] = []
        for site in self._sites:
            position, rotation, _, _ = site_in_axle_frame(robot, site)
            position_task = FramePositionTask(site, position, cfg.ee_position_weight, cfg.ee_kp,
                                              cfg.ee_kv, name=f"position_{site}")  # fmt: skip
            orientation = FrameOrientationTask(site, rotation.copy(), cfg.ee_orientation_weight,
                                               cfg.orientation_kp, cfg.orientation_kv,
                                               name=f"orientation_{site}")  # fmt: skip
            tasks += [self._observed(position_task, cfg.hand_observer_position_bound),
                      self._observed(orientation, cfg.hand_observer_orientation_bound)]  # fmt: skip
            self.orientation_tasks.append(orientation)
            self._orientation_reset.append(rotation.copy())
        columns = np.arange(lay.index_q1 + 1, lay.n_min)
        if len(columns):
            tasks.append(PostureTask(robot.q[columns].copy(),
                                     np.full(len(columns), cfg.posture_weight), cfg.posture_kp,
                                     cfg.posture_kv, columns=columns))  # fmt: skip
        self.tasks = tasks
        self.qp.failures = 0
        # one QP now (creates and compiles the solver object), from the current state
        self.theta_task.theta_d, self.theta_task.thetad_d = robot.theta, robot.thetad
        self.qp.solve(robot, None, self.tasks)  # None: eq. iso3 inside the QP's kernel
        for task in self.tasks:
            if isinstance(task, DisturbanceRejectingTask):
                task.restart()  # the first control step sees this same state again

    def _observed(self, task: Task, bound: float) -> Any:
        """``task`` with the estimate of its unmodelled acceleration, if configured."""
        bandwidth = self.config.hand_observer_bandwidth
        if bandwidth is None:
            return task
        return DisturbanceRejectingTask(task, ObserverSettings(self.task.control_dt, bandwidth,
                                                               bound))  # fmt: skip

    def _set_references(self, robot: RobotModel) -> None:
        ref = self.high_level.reference(robot)
        self.theta_task.theta_d = ref.theta
        self.theta_task.thetad_d = ref.thetad
        self.theta_task.thdd_d = ref.thdd
        if self.spin_task is not None:
            self.spin_task.psi_d = ref.psi
            self.spin_task.psid_d = ref.psid
            self.spin_task.psidd_d = ref.psidd
        if self.config.tray_mode == "specific_force" and self.orientation_tasks:
            tilt = tilt_toward(self._predicted_acceleration(robot), self.config.max_tray_tilt_deg)
            self.orientation_tasks[0].target = tilt @ self._orientation_reset[0]
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
        start = time.perf_counter()
        robot = self.robot
        robot.update(observation["qpos"], observation["qvel"])
        tick = time.perf_counter()
        self._set_references(robot)
        mpc_time = time.perf_counter() - tick
        tick = time.perf_counter()
        solution = self.qp.solve(robot, None, self.tasks)  # None: eq. iso3 in the QP's kernel
        qp_time = time.perf_counter() - tick
        action = np.clip(solution.actuators, self.task.torque_low, self.task.torque_high)
        self._recorder.record(
            t=self._step * self.task.control_dt, wipm_state=wipm_state(robot),
            wipm_reference=self.plan.state(self._ref.mpc_index),
            theta_d=self._ref.theta, thetad_d=self._ref.thetad, thdd_ref=self._ref.thdd,
            tau_0=self._ref.tau_0, torque=action, qp_solved=solution.solved,
            qp_iterations=solution.iterations, qp_failures=self.qp.failures,
            mpc_rejected=self.high_level.mpc.rejected, theta_error=robot.theta - self._ref.theta,
            mpc_time=mpc_time, qp_time=qp_time, compute_time=time.perf_counter() - start,
        )  # fmt: skip
        self._step += 1
        return action

    @property
    def diagnostics(self) -> dict[str, Array]:
        """Per-step ``t``, ``wipm_state``, ``wipm_reference`` (plan at the MPC index),
        ``theta_d``, ``thetad_d``, ``thdd_ref``, ``tau_0`` (MPC), ``torque`` (every actuator),
        ``qp_solved``, ``qp_iterations``, ``qp_failures`` and ``mpc_rejected`` (running counts),
        ``theta_error``, and the timings ``mpc_time``, ``qp_time``, ``compute_time``."""
        return self._recorder.as_arrays()
