"""``decoupled-mpc``: the authors' own in-simulation comparison (reference/krang_facts.md 5.1).

The same high level as the unified controller (offline DDP plan, MPC on the WIPM) drives the
wheels through the WIPM's inverse dynamics: the MPC's ``thdd`` (and ``tau_0``), with the same
feedback on ``theta`` toward the MPC's prediction that the unified controller's theta task uses,
become wheel torques (``controllers.wipm.inverse_dynamics``); the upper body is held at its
posture by joint PD with gravity compensation (the authors locked it). Only the execution of
the plan differs from the unified controller.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import jax
import numpy as np
from numpy.typing import NDArray

from controllers.high_level import HighLevel, HighLevelConfig
from controllers.policy import DiagnosticsRecorder, ModelChoice, TaskInfo, make_robot, task_info
from controllers.posture import PostureHold
from controllers.wipm import inverse_dynamics, planar_inverse_dynamics
from controllers.wipm_problem import wipm_state
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]

_inverse = jax.jit(inverse_dynamics)
_planar_inverse = jax.jit(planar_inverse_dynamics)


@dataclass(frozen=True)
class DecoupledMPCConfig:
    """Settings of ``decoupled-mpc``.

    Attributes:
        model: ``nominal`` or ``oracle``.
        high_level: plan and MPC settings.
        kp_theta, kv_theta: feedback on ``theta`` toward the MPC's prediction (authors' QP:
            KpCOM 50, KvCOM 100 in its COMAngleControl mode).
        posture_frequency_hz, posture_damping_ratio: the upper body's joint PD.
    """

    model: ModelChoice = "nominal"
    high_level: HighLevelConfig = field(default_factory=HighLevelConfig)
    kp_theta: float = 50.0
    kv_theta: float = 100.0
    posture_frequency_hz: float = 5.0
    posture_damping_ratio: float = 1.0


class DecoupledMPCController:
    """MPC on the wheels through the WIPM's inverse dynamics; upper body held."""

    name = "decoupled-mpc"

    def __init__(self, robot: RobotModel, task: TaskInfo, config: DecoupledMPCConfig) -> None:
        self.robot = robot
        self.task = task
        self.config = config
        self.high_level = HighLevel(config.high_level, task.control_dt)
        self._posture = PostureHold(config.posture_frequency_hz, config.posture_damping_ratio)
        self._recorder = DiagnosticsRecorder()

    @classmethod
    def for_env(cls, env: gym.Env, config: DecoupledMPCConfig | None = None
                ) -> DecoupledMPCController:  # fmt: skip
        config = config or DecoupledMPCConfig()
        return cls(make_robot(env, config.model), task_info(env, config.model), config)

    def reset(self, observation: dict[str, Array], info: dict[str, Any]) -> None:
        robot = self.robot
        robot.update(observation["qpos"], observation["qvel"])
        self._recorder.clear()
        self._posture.reset(robot)
        self.plan = self.high_level.reset(robot, self.task.goal, self.task.cup_friction)
        self._step = 0
        # compile the per-step functions now: reset does the slow work
        state = wipm_state(robot)
        if robot.layout.planar:
            _planar_inverse(state, 0.0, self.high_level.params)
        else:
            _inverse(state, np.zeros(2), self.high_level.params)

    @property
    def plan_violations(self) -> tuple[str, ...]:
        return self.plan.violations

    def __call__(self, observation: dict[str, Array]) -> Array:
        start = time.perf_counter()
        robot, lay, cfg = self.robot, self.robot.layout, self.config
        robot.update(observation["qpos"], observation["qvel"])
        ref = self.high_level.reference(robot)
        thdd = (ref.thdd + cfg.kp_theta * (ref.theta - robot.theta)
                + cfg.kv_theta * (ref.thetad - robot.thetad))  # fmt: skip
        state = wipm_state(robot)
        params = self.high_level.params
        action = np.zeros(robot.model.nu)
        wl, wr = lay.wheel_actuators
        if lay.planar:
            action[wl] = action[wr] = 0.5 * float(_planar_inverse(state, thdd, params))
        else:
            tau_left, tau_right = _inverse(state, np.array([thdd, ref.tau_0]), params)
            action[wl], action[wr] = float(tau_left), float(tau_right)
        action[list(lay.joint_actuators)] = self._posture.torques(robot)
        clipped = np.clip(action, self.task.torque_low, self.task.torque_high)
        saturated = bool(np.any(clipped != action))
        last = self.high_level.last_solution
        self._recorder.record(
            t=self._step * self.task.control_dt, wipm_state=state,
            wipm_reference=self.plan.state(ref.mpc_index),
            theta_d=ref.theta, thetad_d=ref.thetad, thdd_ref=ref.thdd, tau_0=ref.tau_0,
            thdd_command=thdd, torque=clipped, saturated=saturated,
            mpc_rejected=self.high_level.mpc.rejected, mpc_cost=last.cost,
            compute_time=time.perf_counter() - start,
        )  # fmt: skip
        self._step += 1
        return clipped

    @property
    def diagnostics(self) -> dict[str, Array]:
        """Per-step ``t``, ``wipm_state`` and ``wipm_reference`` (the plan at the MPC index),
        ``theta_d``, ``thetad_d`` (MPC prediction), ``thdd_ref``, ``tau_0`` (MPC output),
        ``thdd_command`` (with the theta feedback), ``torque``, ``saturated``, ``mpc_rejected``
        (running count), ``mpc_cost``, ``compute_time``."""
        return self._recorder.as_arrays()
