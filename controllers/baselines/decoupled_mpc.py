"""``decoupled-mpc``: the authors' own in-simulation comparison (docs/AUTHORS_CONFIG.md §5.1).

The same high level as the unified controller (offline DDP plan, MPC on the WIPM) drives the
wheels through the WIPM's inverse dynamics: the MPC's ``thdd`` (and ``tau_0``), with the same
feedback on ``theta`` toward the MPC's prediction that the unified controller's theta task uses,
become wheel torques (``controllers.simplified.wipm.inverse_dynamics``). The authors locked every
upper-body joint; here the upper body is held as close to locked as the torque limits allow:
computed torque with the base's expected acceleration as feed-forward plus a stiff joint PD
(``controllers.low_level.posture``), and the largest joint deviation it allowed is reported
(``counters["max_joint_deviation_rad"]``). The hold takes over from the reset state: its
reference starts at the reset's joint positions and velocities and stops the joints over
``posture_stop_time_s`` (``controllers.baselines.stopping_hold``), where a hold toward zero
velocity stopped them in one step. Only the execution of the plan differs from the unified
controller.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import NDArray

from controllers.baselines.decoupled import held_body_counters
from controllers.baselines.stopping_hold import StoppingHold
from controllers.high_level.mpc import param_values, params_from_vector
from controllers.high_level.planning import Plan, PlanConfig
from controllers.high_level.receding_horizon import HighLevel, HighLevelConfig
from controllers.optimizer import jax_setup
from controllers.policy import ModelChoice, PolicyBase, TaskInfo
from controllers.simplified.wipm import (
    inverse_dynamics,
    planar_dynamics,
    planar_inverse_dynamics,
    spatial_dynamics,
)
from controllers.simplified.wipm_problem import wipm_state
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]


def _planar_command(state: Array, thdd: Array, packed: Array) -> jax.Array:
    """``[tau_w, xdd]``: the wheels' torque that realises ``thdd`` and the axle's acceleration
    it gives (``lambda(q)`` packed: ``controllers.high_level.mpc.param_values``)."""
    params = params_from_vector(packed)
    tau_w = planar_inverse_dynamics(state, thdd, params)
    return jnp.stack([tau_w, planar_dynamics(state, thdd, params)[3]])


def _spatial_command(state: Array, u: Array, packed: Array) -> jax.Array:
    """``[tau_L, tau_R, xdd, psidd]`` for ``u = [thdd, tau_0]`` (as :func:`_planar_command`)."""
    params = params_from_vector(packed)
    tau_left, tau_right = inverse_dynamics(state, u, params)
    sdot = spatial_dynamics(state, u, params)
    return jnp.stack([tau_left, tau_right, sdot[3], sdot[4]])


# one jitted call per control step, its result fetched whole: two calls with lambda(q)'s 11
# leaves each and JAX-array indexing (an operation per index) cost ~0.57 ms a step
# in float64 whatever the process's JAX settings (jax_setup; about 2 us a control step)
_planar_command_jit = jax_setup.in_float64(jax.jit(_planar_command))
_spatial_command_jit = jax_setup.in_float64(jax.jit(_spatial_command))


@dataclass(frozen=True)
class DecoupledMPCConfig:
    """Settings of ``decoupled-mpc``.

    Attributes:
        model: ``nominal`` or ``oracle``.
        high_level: plan and MPC settings.
        kp_theta, kv_theta: feedback on ``theta`` toward the MPC's prediction (authors' QP:
            KpCOM 50, KvCOM 100 in its COMAngleControl mode).
        posture_frequency_hz, posture_damping_ratio: the stiff joint PD of the computed
            torque that holds the upper body (20 Hz, critically damped: 16 control steps per
            period at 1 kHz; the authors locked the joints rigidly).
        posture_stop_time_s: how long the hold takes to stop the joints' reset velocities (a
            minimum-jerk stop, ``controllers.baselines.stopping_hold``): 0.1 s, two periods of
            the hold, measured against 0 s (the step stop) in docs/controllers.md §3.
    """

    model: ModelChoice = "nominal"
    high_level: HighLevelConfig = field(default_factory=HighLevelConfig)
    kp_theta: float = 50.0
    kv_theta: float = 100.0
    posture_frequency_hz: float = 20.0
    posture_damping_ratio: float = 1.0
    posture_stop_time_s: float = 0.1

    @classmethod
    def paper(cls) -> DecoupledMPCConfig:
        """The authors' plan (``PlanConfig.paper()``) under our MPC and joint hold."""
        return cls(high_level=HighLevelConfig(plan=PlanConfig.paper()))


class DecoupledMPCController(PolicyBase):
    """MPC on the wheels through the WIPM's inverse dynamics; upper body held."""

    config_class = DecoupledMPCConfig
    registry_name = "decoupled-mpc"

    def __init__(self, robot: RobotModel, task: TaskInfo, config: DecoupledMPCConfig) -> None:
        super().__init__(robot, task, config)
        self.high_level = HighLevel(config.high_level, task.control_dt)
        self._posture = StoppingHold(
            config.posture_frequency_hz, config.posture_damping_ratio, config.posture_stop_time_s
        )
        self.plan: Plan | None = None

    def reset(self, observation: dict[str, Array], info: dict[str, Any]) -> None:
        robot = self.robot
        robot.update(observation["qpos"], observation["qvel"])
        self.begin_episode()
        self._posture.reset(robot)
        self.plan = self.high_level.reset(robot, self.task.goal, self.task.cup_friction)
        self._packed: tuple[object, Array] | None = None
        # compile the per-step function now: reset does the slow work
        state = wipm_state(robot)
        if robot.layout.planar:
            _planar_command_jit(state, 0.0, self._packed_params())
        else:
            _spatial_command_jit(state, np.zeros(2), self._packed_params())

    @property
    def plan_violations(self) -> tuple[str, ...]:
        return () if self.plan is None else self.plan.violations

    def __call__(self, observation: dict[str, Array]) -> Array:
        if self.plan is None:
            raise RuntimeError(f"{type(self).__name__}: reset() before the first step")
        plan = self.plan
        start = time.perf_counter()
        robot, lay, cfg = self.robot, self.robot.layout, self.config
        robot.update(observation["qpos"], observation["qvel"])
        ref = self.high_level.reference(robot)
        thdd = (
            ref.thdd
            + cfg.kp_theta * (ref.theta - robot.theta)
            + cfg.kv_theta * (ref.thetad - robot.thetad)
        )
        state = wipm_state(robot)
        packed = self._packed_params()
        # the base's expected acceleration (the joints held, q1dd = thdd): the computed
        # torque's feed-forward
        if lay.planar:
            tau_w, xdd = np.asarray(_planar_command_jit(state, thdd, packed)).tolist()
            wheels = (0.5 * tau_w, 0.5 * tau_w)
            base = np.array([xdd, thdd])
        else:
            u = np.array([thdd, ref.tau_0])
            tau_left, tau_right, xdd, psidd = np.asarray(
                _spatial_command_jit(state, u, packed)
            ).tolist()
            wheels = (tau_left, tau_right)
            base = np.array([xdd, psidd, thdd])
        t = self._step * self.task.control_dt
        applied = self.finish(self.assemble(wheels, self._posture.torques(robot, base, t=t)))
        last = self.high_level.last_solution
        self._recorder.record(
            t=t,
            wipm_state=state,
            wipm_reference=plan.state(ref.mpc_index),
            theta_d=ref.theta,
            thetad_d=ref.thetad,
            thdd_ref=ref.thdd,
            tau_0=ref.tau_0,
            thdd_command=thdd,
            torque=applied,
            clip_excess=self._clip.last_excess,
            joint_deviation=self._posture.last_deviation,
            mpc_rejected=self.high_level.rejections,
            mpc_cost=last.cost,
            compute_time=time.perf_counter() - start,
        )
        self._step += 1
        return applied

    def _packed_params(self) -> Array:
        """``HighLevel.params`` (``lambda(q)`` of the latest MPC solve started, as before) as one
        vector (``param_values``), made again when they change: once per MPC step."""
        params = self.high_level.params
        if self._packed is None or self._packed[0] is not params:
            self._packed = (params, np.array(param_values(params)))
        return self._packed[1]

    def controller_counters(self) -> dict[str, float]:
        counters = held_body_counters(self._posture, self.plan)
        if self.high_level.mpc is not None:
            counters["mpc_rejections"] = float(self.high_level.rejections)
        return counters

    @property
    def diagnostics(self) -> dict[str, Array]:
        """Per-step ``t``, ``wipm_state`` and ``wipm_reference`` (the plan at the MPC index),
        ``theta_d``, ``thetad_d`` (MPC prediction), ``thdd_ref``, ``tau_0`` (MPC output),
        ``thdd_command`` (with the theta feedback), ``torque`` (applied), ``clip_excess`` (N m
        by which the action exceeded its bounds), ``joint_deviation`` (rad), ``mpc_rejected``
        (running count), ``mpc_cost``, ``compute_time``."""
        return self._recorder.as_arrays()
