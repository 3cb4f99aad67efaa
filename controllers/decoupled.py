"""The "traditional" Krang controller the paper compares against (reference/krang_facts.md 5.2).

The wheels balance the whole robot as one inverted pendulum by LQR state feedback on
``theta, thetad, x, xd`` (and ``psi, psid`` in 3-D) plus an integral of the position error, so
a CoM the nominal model gets slightly wrong still ends at the goal. The model is the WIPM
(paper section "Simplified Model") with the wheel torques as inputs, i.e. its ``x`` and
``theta`` rows before the torque is eliminated (ERRATA 1) and, in 3-D, its spin row,
linearised at balance by ``jax.jacfwd`` and discretised (zero-order hold) at the control step.
The upper body is held at its initial posture by joint PD with gravity compensation, blind to
balance. Krang's own gains were hand-tuned currents (BAL_LO: 277.4, 61.889, 7.4484, 18.235 A);
ours come from the LQR solve, with weights below.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from controllers.lqr import dlqr, zero_order_hold
from controllers.planning import Plan, PlanConfig, plan_to_goal
from controllers.policy import DiagnosticsRecorder, ModelChoice, TaskInfo, make_robot, task_info
from controllers.posture import PostureHold
from controllers.reference import GoalReference
from controllers.wipm import (
    linearize,
    params_from_lambda,
    planar_torque_dynamics,
    spatial_torque_dynamics,
)
from controllers.wipm_problem import wipm_state
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]


@dataclass(frozen=True)
class DecoupledConfig:
    """Weights and gains of the decoupled controller.

    Attributes:
        model: ``nominal`` (robot + tray as designed) or ``oracle`` (the env's exact model).
        q_theta, q_thetad, q_x, q_xd, q_x_integral: LQR state weights (rad, rad/s, m, m/s, m s).
            The 2014 hardware LQR (krang_facts 5.2) weighted diag(300, 96000, 30000, 90000) on
            wheel radians with R = 500 on amps; ours are in SI units on the WIPM's state.
        q_psi, q_psid: heading weights (3-D).
        r_torque: weight on each wheel torque (N m)^-2.
        reference: ``plan`` (default): track the offline DDP plan of the WIPM (the one every
            compared controller follows, so only the execution differs), states ``theta``,
            ``x``, ``psi`` and their rates; ``minimum_jerk``: Krang 2014's style, ``theta_ref =
            0`` and a smooth position profile (turn to face the goal, then drive).
        plan: the offline plan's settings (``reference = "plan"``).
        max_acceleration: peak acceleration of the minimum-jerk reference (m/s^2).
        max_spin_acceleration: peak heading acceleration of that reference (rad/s^2).
        posture_frequency_hz, posture_damping_ratio: the joint PD holding the upper body, set per
            joint from its inertia at reset (``Kp = A_jj w^2``, ``Kd = 2 zeta A_jj w``).
    """

    model: ModelChoice = "nominal"
    q_theta: float = 100.0
    q_thetad: float = 10.0
    q_x: float = 100.0
    q_xd: float = 10.0
    q_x_integral: float = 20.0
    q_psi: float = 100.0
    q_psid: float = 10.0
    r_torque: float = 1e-3
    reference: Literal["plan", "minimum_jerk"] = "plan"
    plan: PlanConfig = field(default_factory=PlanConfig)
    max_acceleration: float = 0.3
    max_spin_acceleration: float = 0.5
    posture_frequency_hz: float = 5.0
    posture_damping_ratio: float = 1.0


class DecoupledController:
    """LQR wheel balance + joint-PD upper body (see the module docstring)."""

    name = "decoupled"

    def __init__(self, robot: RobotModel, task: TaskInfo, config: DecoupledConfig) -> None:
        self.robot = robot
        self.task = task
        self.config = config
        self._recorder = DiagnosticsRecorder()
        self._planar = robot.layout.planar
        self._K = np.zeros((0, 0))
        self._reference: Callable[[float], dict[str, float]] | None = None
        self._posture = PostureHold(config.posture_frequency_hz, config.posture_damping_ratio)
        self._step = 0

    @classmethod
    def for_env(cls, env: gym.Env, config: DecoupledConfig | None = None) -> DecoupledController:
        config = config or DecoupledConfig()
        return cls(make_robot(env, config.model), task_info(env, config.model), config)

    # ----------------------------------------------------------------- reset
    def reset(self, observation: dict[str, Array], info: dict[str, Any]) -> None:
        robot, cfg = self.robot, self.config
        robot.update(observation["qpos"], observation["qvel"])
        self._recorder.clear()
        self._step = 0
        self._integral = 0.0
        lam = robot.wipm_parameters()
        if lam.com_distance < 1e-3:
            raise ValueError(
                f"LQR problem ill-posed: the body CoM is {lam.com_distance:.2e} m from the axle "
                "(no pendulum left to balance at this posture)"
            )
        params = params_from_lambda(lam)
        if self._planar:
            s0, u0 = np.zeros(4), np.zeros(1)
            A, B = (
                np.asarray(a)
                for a in linearize(
                    lambda s, u, p: planar_torque_dynamics(s, u[0], p), s0, u0, params
                )
            )
            # state [theta, thetad, x, xd]; input total wheel torque
            weights = [cfg.q_theta, cfg.q_thetad, cfg.q_x, cfg.q_xd]
            x_index = 2
        else:
            s0, u0 = np.zeros(8), np.zeros(2)
            A8, B8 = (np.asarray(a) for a in linearize(spatial_torque_dynamics, s0, u0, params))
            A, B = A8[:6, :6], B8[:6]
            # state [x, psi, theta, xd, psid, thetad]; inputs (tau_L, tau_R)
            weights = [cfg.q_x, cfg.q_psi, cfg.q_theta, cfg.q_xd, cfg.q_psid, cfg.q_thetad]
            x_index = 0
        n, m = B.shape
        A_aug = np.zeros((n + 1, n + 1))
        A_aug[:n, :n] = A
        A_aug[n, x_index] = 1.0  # d/dt of the integral of the position error
        B_aug = np.vstack([B, np.zeros((1, m))])
        Ad, Bd = zero_order_hold(A_aug, B_aug, self.task.control_dt)
        Q = np.diag([*weights, cfg.q_x_integral])
        R = cfg.r_torque * np.eye(m)
        self._K, _ = dlqr(Ad, Bd, Q, R)
        self._closed_loop = Ad - Bd @ self._K
        self._x_index = x_index
        self._posture.reset(robot)

        axle = robot.axle_position
        if cfg.reference == "plan":
            self.plan: Plan | None = plan_to_goal(
                wipm_state(robot),
                params,
                self.task.goal,
                planar=self._planar,
                cup_friction=self.task.cup_friction,
                config=cfg.plan,
            )
            self._reference = self.plan.sample
            return
        if cfg.reference != "minimum_jerk":
            raise ValueError(f"reference must be 'plan' or 'minimum_jerk', got {cfg.reference!r}")
        self.plan = None
        self._reference = GoalReference.to_goal(
            axle[:2],
            robot.psi,
            self.task.goal,
            x0=float(robot.q[0]),
            max_acceleration=cfg.max_acceleration,
            max_spin_acceleration=cfg.max_spin_acceleration,
            planar=self._planar,
        )

    @property
    def gains(self) -> Array:
        """The LQR gain on ``[state error, integral of the position error]``."""
        return self._K

    @property
    def closed_loop_matrix(self) -> Array:
        """``Ad - Bd K`` of the augmented discrete model (eigenvalues inside the unit circle)."""
        return self._closed_loop

    @property
    def reference(self) -> Callable[[float], dict[str, float]]:
        """The reference as a function of time: the plan's states, or the minimum-jerk
        profile (``theta_ref = 0``)."""
        if self._reference is None:
            raise RuntimeError("reset() first")
        return self._reference

    # ------------------------------------------------------------------ step
    def __call__(self, observation: dict[str, Array]) -> Array:
        start = time.perf_counter()
        robot, lay = self.robot, self.robot.layout
        robot.update(observation["qpos"], observation["qvel"])
        t = self._step * self.task.control_dt
        ref = self.reference(t)
        q, nu = robot.q, robot.nu
        x_error = q[0] - ref["x"]
        theta_error = robot.theta - ref.get("theta", 0.0)
        thetad_error = robot.thetad - ref.get("thetad", 0.0)
        if self._planar:
            error = np.array([theta_error, thetad_error, x_error, nu[0] - ref["xd"]])
        else:
            error = np.array(
                [
                    x_error,
                    q[1] - ref["psi"],
                    theta_error,
                    nu[0] - ref["xd"],
                    nu[1] - ref["psid"],
                    thetad_error,
                ]
            )
        u = -self._K @ np.append(error, self._integral)
        self._integral += x_error * self.task.control_dt
        action = np.zeros(robot.model.nu)
        wl, wr = lay.wheel_actuators
        if self._planar:
            action[wl] = action[wr] = 0.5 * u[0]
        else:
            action[wl], action[wr] = u
        action[list(lay.joint_actuators)] = self._posture.torques(robot)
        clipped = np.clip(action, self.task.torque_low, self.task.torque_high)
        saturated = bool(np.any(clipped != action))
        self._step += 1
        self._recorder.record(
            t=t,
            x=q[0],
            x_ref=ref["x"],
            xd=nu[0],
            xd_ref=ref["xd"],
            theta=robot.theta,
            thetad=robot.thetad,
            psi=robot.psi,
            psi_ref=ref.get("psi", 0.0),
            theta_ref=ref.get("theta", 0.0),
            torque=clipped,
            saturated=saturated,
            compute_time=time.perf_counter() - start,
        )
        return clipped

    @property
    def diagnostics(self) -> dict[str, Array]:
        """Per-step ``t, x, x_ref, xd, xd_ref, theta, theta_ref, thetad, psi, psi_ref, torque,
        saturated,
        compute_time`` (torques after saturation; ``saturated`` marks steps where the
        controller limited a torque to the actuator's range itself)."""
        return self._recorder.as_arrays()
