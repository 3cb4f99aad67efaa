"""The "traditional" decoupled Krang controllers the paper compares against: the wheels
balance the whole robot as one inverted pendulum, the upper body is held at its posture by
joint PD with gravity compensation (``controllers.low_level.posture``), blind to balance. The
hold stops the joints' reset velocities in one step (``posture_stop_time_s = 0``: at 5 Hz that
step does not show in the cup's friction peak on the default scenario or the paper's Krang;
``decoupled-mpc``'s 20 Hz hold stops them over 0.1 s, docs/controllers.md §3).

* :class:`DecoupledController` (registry ``decoupled``): Krang 2014 as published
  (docs/AUTHORS_CONFIG.md §5.2). It balances about ``theta_ref = 0``, ``thetad_ref = 0`` and
  tracks the offline plan's ``x`` and ``xd`` (Krang's joystick references, replaced by the plan
  every compared controller follows), with the hand-tuned BAL_LO gains converted from motor
  current to wheel torque (1.2711 N m/A per wheel): 352.6 N m/rad and 78.7 N m s/rad on
  ``theta``, 9.47 N m and 23.2 N m s per radian of wheel angle on ``x`` (37.9 N m/m and
  92.7 N m s/m at R = 0.25), and -10 A (12.7 N m s) per wheel radian per second on the spin
  rate. Its currents are clamped where the published code clamps them: the spin term
  ``u_spin`` at +-30 A, then each wheel's ``u_theta + u_x +- u_spin`` at +-50 A (the
  simulation's value; 49 A on the hardware), i.e. 63.6 N m per wheel; ``u_theta`` and ``u_x``
  have no clamp of their own (docs/AUTHORS_CONFIG.md §5.2). Every robot's wheels take
  150 N m, so the same clamps apply on each; the steps each clamp acted on are counted
  (``spin_current_clamped_steps``, ``wheel_current_clamped_steps``). BAL_LO has no
  heading-position gain (its spin-position gain K4 is 0); for goals off
  the x axis we add one (our addition, not Krang's): ``heading_gain_amps``, 2.5 A (3.2 N m)
  per wheel radian of spin, the smallest that tracks the plan's heading. Measured on
  KrangTray-v0, goal (2, 1.5), seed 0, 10 s: at the plan's arrival (8.98 s) the heading error
  is 2.8 deg with 0.5 N m, 1.3 deg with 1.5 N m (not tracking, by a 1 deg criterion), 0.44
  deg with 3.2 N m (this gain) and 0.2 deg with 13 N m. A stiffer heading does not bring the
  robot nearer its goal: ``x`` lags the plan (no lean is planned for it), so a heading that
  keeps the plan's timing turns too early on the path; the robot ended 4.3 cm from the goal
  with 3.2 N m and 28 cm with 13 N m.
* :class:`DecoupledLQRController` (registry ``decoupled-lqr``): our stronger variant. An LQR
  on the WIPM (paper section "Simplified Model") with the wheel torques as inputs, i.e. its
  ``x`` and ``theta`` rows before the torque is eliminated (docs/ERRATA.md §1) and, in 3-D, its spin
  row, linearised at balance by ``jax.jacfwd`` and discretised (zero-order hold) at the control
  step, tracks the plan's *lean* ``theta`` as well as ``x`` (and ``psi``), with an integral of
  the position error. Its gains are 2 to 9 times stiffer than Krang's, and tracking the
  planned lean lets it accelerate as the plan does: it is not the original. It has no current
  clamp: only the actuators' torque limits bound it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from controllers.baselines.lqr import dlqr, zero_order_hold
from controllers.baselines.minimum_jerk import GoalReference
from controllers.baselines.stopping_hold import StoppingHold
from controllers.high_level.planning import Plan, PlanConfig, plan_to_goal
from controllers.low_level.posture import PostureHold
from controllers.optimizer import jax_setup
from controllers.policy import ModelChoice, PolicyBase, TaskInfo, plan_counters
from controllers.simplified.wipm import (
    WIPMParams,
    linearize,
    params_from_lambda,
    planar_torque_dynamics,
    spatial_torque_dynamics,
)
from controllers.simplified.wipm_problem import wipm_state
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]

# Krang's BAL_LO mode (docs/AUTHORS_CONFIG.md §5.2): amps per (rad, rad/s) of theta_com, per
# (rad, rad/s) of wheel angle, per (rad, rad/s) of spin (in wheel radians)
BAL_LO_AMPS = (277.4, 61.889, 7.4484, 18.235, 0.0, -10.0)
# wheel torque per amp of one wheel's motor: 12 oz-in/A x 0.00706155 N m/oz-in x 15:1 gear
KRANG_TORQUE_PER_AMP = 1.2711
# the published clamps (docs/AUTHORS_CONFIG.md §5.2): the spin current (46 src/control.cpp;
# 15 A in the earlier KS code) and each wheel's current (46's simulation config; 49 A on the
# hardware)
KRANG_SPIN_CURRENT_LIMIT = 30.0
KRANG_WHEEL_CURRENT_LIMIT = 50.0


@dataclass(frozen=True)
class KrangCurrents:
    """One step of Krang 2014's current law (docs/AUTHORS_CONFIG.md §5.2), in amps.

    Attributes:
        theta, x, spin: the terms ``u_theta``, ``u_x``, ``u_spin`` as computed (``spin``
            before its clamp).
        wheels: ``(i_L, i_R)`` applied, after both clamps.
        spin_clamped, wheel_clamped: whether the spin clamp, or either wheel's clamp, acted.
    """

    theta: float
    x: float
    spin: float
    wheels: tuple[float, float]
    spin_clamped: bool
    wheel_clamped: bool


def krang_currents(
    theta: float, x: float, spin: float, spin_limit: float, wheel_limit: float
) -> KrangCurrents:
    """The wheel currents from the terms ``u_theta``, ``u_x``, ``u_spin`` (A) with the published
    clamps: ``u_spin`` to ``+-spin_limit``, then ``i_L = u_theta + u_x + u_spin`` and ``i_R =
    u_theta + u_x - u_spin`` each to ``+-wheel_limit``; ``u_theta`` and ``u_x`` have no clamp of
    their own."""
    clamped_spin = min(max(spin, -spin_limit), spin_limit)
    common = theta + x
    left, right = common + clamped_spin, common - clamped_spin
    wheels = (
        min(max(left, -wheel_limit), wheel_limit),
        min(max(right, -wheel_limit), wheel_limit),
    )
    return KrangCurrents(
        theta=theta,
        x=x,
        spin=spin,
        wheels=wheels,
        spin_clamped=clamped_spin != spin,
        wheel_clamped=wheels != (left, right),
    )


def _check_body(robot: RobotModel) -> None:
    lam = robot.wipm_parameters()
    if lam.com_distance < 1e-3:
        raise ValueError(
            f"LQR problem ill-posed: the body CoM is {lam.com_distance:.2e} m from the axle "
            "(no pendulum left to balance at this posture)"
        )


def _plan(robot: RobotModel, params: WIPMParams, task: TaskInfo, config: PlanConfig) -> Plan:
    return plan_to_goal(
        wipm_state(robot),
        params,
        task.goal,
        planar=robot.layout.planar,
        cup_friction=task.cup_friction,
        config=config,
    )


# ------------------------------------------------------------------ Krang 2014 as published


def held_body_counters(posture: PostureHold, plan: Plan | None) -> dict[str, float]:
    """The counters of a controller that holds the body and follows a plan: the largest joint
    deviation the hold allowed, and the plan's violations and convergence."""
    counters = {"max_joint_deviation_rad": posture.max_deviation}
    if plan is not None:
        counters.update(plan_counters(plan))
    return counters


@dataclass(frozen=True)
class DecoupledConfig:
    """Krang 2014's balance controller (docs/AUTHORS_CONFIG.md §5.2).

    Attributes:
        model: ``nominal`` (robot + tray as designed) or ``oracle`` (the env's exact model).
        gains_amps: the BAL_LO currents ``(K_theta, K_thetad, K_x, K_xd, K_spin, K_spin_rate)``
            in A per rad (or rad/s) of ``theta_com``, of wheel angle ``x / R`` and of spin in
            wheel radians ``(sep / 2R) psi``; the spin term enters as ``-(K4 e4 + K5 e5)``,
            added to the left wheel and subtracted from the right.
        torque_per_amp: wheel torque per motor amp, 1.2711 N m/A (the AMC/BLY343D drive with
            its 15:1 gearbox; docs/AUTHORS_CONFIG.md §1.5).
        spin_current_limit_amps: the clamp of ``u_spin`` (our heading term included), 30 A as
            in 46's ``src/control.cpp`` (15 A in the earlier KS code; docs/AUTHORS_CONFIG.md
            §5.2).
        wheel_current_limit_amps: the clamp of each wheel's current ``u_theta + u_x +-
            u_spin``, 50 A as in 46's simulation config (49 A on the hardware), 63.6 N m per
            wheel at ``torque_per_amp`` (docs/AUTHORS_CONFIG.md §1.5, §5.2).
        heading_gain_amps: our addition, A per wheel radian of spin error (3-D), entering as
            ``-heading_gain_amps`` in BAL_LO's spin-position slot (module docstring).
        plan: the offline plan whose ``x``, ``xd`` (and ``psi``, ``psid``) are tracked.
        posture_frequency_hz, posture_damping_ratio: the joint PD holding the upper body.
        posture_stop_time_s: how long the hold takes to stop the joints' reset velocities
            (``controllers.baselines.stopping_hold``): 0, in one step, as ``PostureHold``; at
            5 Hz the step does not show in the cup's friction peak (docs/controllers.md §3).
    """

    model: ModelChoice = "nominal"
    gains_amps: tuple[float, float, float, float, float, float] = BAL_LO_AMPS
    torque_per_amp: float = KRANG_TORQUE_PER_AMP
    spin_current_limit_amps: float = KRANG_SPIN_CURRENT_LIMIT
    wheel_current_limit_amps: float = KRANG_WHEEL_CURRENT_LIMIT
    heading_gain_amps: float = 2.5
    plan: PlanConfig = field(default_factory=PlanConfig)
    posture_frequency_hz: float = 5.0
    posture_damping_ratio: float = 1.0
    posture_stop_time_s: float = 0.0

    def __post_init__(self) -> None:
        if len(self.gains_amps) != 6 or not np.all(np.isfinite(self.gains_amps)):
            raise ValueError(f"gains_amps must be 6 finite numbers, got {self.gains_amps!r}")
        if not self.torque_per_amp > 0:
            raise ValueError(f"torque_per_amp must be positive, got {self.torque_per_amp!r}")
        for name in ("spin_current_limit_amps", "wheel_current_limit_amps"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)!r}")
        if not self.heading_gain_amps >= 0:
            raise ValueError(f"heading_gain_amps must be >= 0, got {self.heading_gain_amps!r}")

    @classmethod
    def paper(cls) -> DecoupledConfig:
        """The published gains, following the authors' plan (``PlanConfig.paper()``)."""
        return cls(plan=PlanConfig.paper())

    @property
    def wheel_gains(self) -> Array:
        """Per-wheel torque gains (N m per rad or rad/s of the state in Krang's units)."""
        return self.torque_per_amp * np.asarray(self.gains_amps, dtype=float)


class DecoupledController(PolicyBase):
    """Krang 2014: BAL_LO state feedback about ``theta = 0`` on the plan's ``x``, ``xd``."""

    config_class = DecoupledConfig
    registry_name = "decoupled"

    def __init__(self, robot: RobotModel, task: TaskInfo, config: DecoupledConfig) -> None:
        super().__init__(robot, task, config)
        self._posture = StoppingHold(
            config.posture_frequency_hz, config.posture_damping_ratio, config.posture_stop_time_s
        )
        self.plan: Plan | None = None
        self._heading_amps = 0.0
        self._spin_clamped_steps = 0
        self._wheel_clamped_steps = 0

    def reset(self, observation: dict[str, Array], info: dict[str, Any]) -> None:
        robot, cfg = self.robot, self.config
        robot.update(observation["qpos"], observation["qvel"])
        self.begin_episode()
        self._spin_clamped_steps = 0
        self._wheel_clamped_steps = 0
        _check_body(robot)
        params = params_from_lambda(robot.wipm_parameters())
        self._posture.reset(robot)
        lay = robot.layout
        self._spin_per_heading = lay.wheel_separation / (2.0 * lay.wheel_radius)
        self._heading_amps = 0.0 if lay.planar else cfg.heading_gain_amps
        self.plan = _plan(robot, params, self.task, cfg.plan)

    @property
    def heading_gain(self) -> float:
        """The heading gain in use (N m per wheel radian of spin; 0 planar)."""
        return self.config.torque_per_amp * self._heading_amps

    def __call__(self, observation: dict[str, Array]) -> Array:
        start = time.perf_counter()
        robot, lay = self.robot, self.robot.layout
        robot.update(observation["qpos"], observation["qvel"])
        if self.plan is None:
            raise RuntimeError("reset() first")
        t = self._step * self.task.control_dt
        ref = self.plan.sample(t)
        q, nu = robot.q, robot.nu
        cfg = self.config
        k = cfg.gains_amps
        R = lay.wheel_radius
        # theta_ref = 0, thetad_ref = 0 (Krang 2014); x in wheel radians; currents in A
        u_theta = k[0] * robot.theta + k[1] * robot.thetad
        u_x = k[2] * (q[0] - ref["x"]) / R + k[3] * (nu[0] - ref["xd"]) / R
        u_spin = 0.0
        if not lay.planar:
            n = self._spin_per_heading
            spin_error = n * (q[1] - ref["psi"])
            spin_rate_error = n * (nu[1] - ref["psid"])
            # Krang: u_spin = -(K4 e4 + K5 e5), plus our heading term, left +, right -
            u_spin = -(k[4] * spin_error + k[5] * spin_rate_error) + self._heading_amps * spin_error
        currents = krang_currents(
            u_theta, u_x, u_spin, cfg.spin_current_limit_amps, cfg.wheel_current_limit_amps
        )
        self._spin_clamped_steps += currents.spin_clamped
        self._wheel_clamped_steps += currents.wheel_clamped
        wheels = (
            cfg.torque_per_amp * currents.wheels[0],
            cfg.torque_per_amp * currents.wheels[1],
        )
        action = self.assemble(wheels, self._posture.torques(robot, t=t))
        applied = self.finish(action)
        self._step += 1
        self._recorder.record(
            t=t,
            x=q[0],
            x_ref=ref["x"],
            xd=nu[0],
            xd_ref=ref["xd"],
            theta=robot.theta,
            thetad=robot.thetad,
            theta_ref=0.0,
            thetad_ref=0.0,
            psi=robot.psi,
            psi_ref=ref.get("psi", 0.0),
            current_theta=u_theta,
            current_x=u_x,
            current_spin=u_spin,
            wheel_current=currents.wheels,
            torque=applied,
            clip_excess=self._clip.last_excess,
            joint_deviation=self._posture.last_deviation,
            compute_time=time.perf_counter() - start,
        )
        return applied

    def controller_counters(self) -> dict[str, float]:
        return {
            **held_body_counters(self._posture, self.plan),
            "spin_current_clamped_steps": float(self._spin_clamped_steps),
            "wheel_current_clamped_steps": float(self._wheel_clamped_steps),
        }

    @property
    def diagnostics(self) -> dict[str, Array]:
        """Per-step ``t, x, x_ref, xd, xd_ref, theta, thetad, theta_ref, thetad_ref`` (both 0),
        ``psi, psi_ref``, the current terms ``current_theta``, ``current_x``, ``current_spin``
        (A, the spin term before its clamp), ``wheel_current`` (``(i_L, i_R)`` applied, A),
        ``torque`` (applied), ``clip_excess`` (N m by which the action exceeded its bounds),
        ``joint_deviation`` (largest body-joint deviation from the held posture, rad),
        ``compute_time``."""
        return self._recorder.as_arrays()


# ----------------------------------------------------------------------- our stronger LQR
@dataclass(frozen=True)
class DecoupledLQRConfig:
    """Weights and gains of ``decoupled-lqr`` (stronger than Krang's: module docstring).

    Attributes:
        model: ``nominal`` (robot + tray as designed) or ``oracle`` (the env's exact model).
        q_theta, q_thetad, q_x, q_xd, q_x_integral: LQR state weights (rad, rad/s, m, m/s, m s).
            The 2014 hardware LQR (docs/AUTHORS_CONFIG.md §5.2) weighted diag(300, 96000,
            30000, 90000) on wheel radians with R = 500 on amps; ours are in SI units on the
            WIPM's state.
        q_psi, q_psid: heading weights (3-D).
        r_torque: weight on each wheel torque (N m)^-2.
        reference: ``plan`` (default): track the offline DDP plan of the WIPM (the one every
            compared controller follows, so only the execution differs), states ``theta``,
            ``x``, ``psi`` and their rates; ``minimum_jerk``: ``theta_ref = 0`` and a smooth
            position profile (turn to face the goal, then drive).
        plan: the offline plan's settings (``reference = "plan"``).
        max_acceleration: peak acceleration of the minimum-jerk reference (m/s^2).
        max_spin_acceleration: peak heading acceleration of that reference (rad/s^2).
        posture_frequency_hz, posture_damping_ratio: the joint PD holding the upper body, set per
            joint from its inertia at reset (``Kp = A_jj w^2``, ``Kd = 2 zeta A_jj w``).
        posture_stop_time_s: how long the hold takes to stop the joints' reset velocities: 0,
            in one step (as ``DecoupledConfig``'s).
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
    posture_stop_time_s: float = 0.0

    def __post_init__(self) -> None:
        if self.reference not in ("plan", "minimum_jerk"):
            raise ValueError(f"reference must be 'plan' or 'minimum_jerk', got {self.reference!r}")

    @classmethod
    def paper(cls) -> DecoupledLQRConfig:
        """Our LQR following the authors' plan (``PlanConfig.paper()``)."""
        return cls(plan=PlanConfig.paper())


class DecoupledLQRController(PolicyBase):
    """LQR wheel balance on the plan's lean + joint-PD upper body (module docstring)."""

    config_class = DecoupledLQRConfig
    registry_name = "decoupled-lqr"

    def __init__(self, robot: RobotModel, task: TaskInfo, config: DecoupledLQRConfig) -> None:
        super().__init__(robot, task, config)
        self._planar = robot.layout.planar
        self._K = np.zeros((0, 0))
        self._reference: Callable[[float], dict[str, float]] | None = None
        self._posture = StoppingHold(
            config.posture_frequency_hz, config.posture_damping_ratio, config.posture_stop_time_s
        )
        self.plan: Plan | None = None

    # ----------------------------------------------------------------- reset
    def reset(self, observation: dict[str, Array], info: dict[str, Any]) -> None:
        robot, cfg = self.robot, self.config
        robot.update(observation["qpos"], observation["qvel"])
        self.begin_episode()
        self._integral = 0.0
        _check_body(robot)
        params = params_from_lambda(robot.wipm_parameters())
        if self._planar:
            s0, u0 = np.zeros(4), np.zeros(1)
            with jax_setup.float64():  # JAX's linearisation in float64 (docs/DESIGN.md §4)
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
            with jax_setup.float64():
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
        self._continuous = (A_aug, B_aug)
        Ad, Bd = zero_order_hold(A_aug, B_aug, self.task.control_dt)
        Q = np.diag([*weights, cfg.q_x_integral])
        R = cfg.r_torque * np.eye(m)
        self._K, self._P = dlqr(Ad, Bd, Q, R)
        self._discrete = (Ad, Bd, Q, R)
        self._closed_loop = Ad - Bd @ self._K
        self._x_index = x_index
        self._posture.reset(robot)

        axle = robot.axle_position
        if cfg.reference == "plan":
            self.plan = _plan(robot, params, self.task, cfg.plan)
            self._reference = self.plan.sample
            return
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
    def riccati(self) -> tuple[Array, Array, Array, Array, Array]:
        """``(Ad, Bd, Q, R, P)``: the discrete model, the weights and the Riccati solution."""
        return (*self._discrete, self._P)

    @property
    def continuous_model(self) -> tuple[Array, Array]:
        """``(A, B)`` of the augmented continuous-time linearisation."""
        return self._continuous

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
        robot = self.robot
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
        wheels = (0.5 * u[0], 0.5 * u[0]) if self._planar else (u[0], u[1])
        applied = self.finish(self.assemble(wheels, self._posture.torques(robot, t=t)))
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
            torque=applied,
            clip_excess=self._clip.last_excess,
            joint_deviation=self._posture.last_deviation,
            compute_time=time.perf_counter() - start,
        )
        return applied

    def controller_counters(self) -> dict[str, float]:
        return held_body_counters(self._posture, self.plan)

    @property
    def diagnostics(self) -> dict[str, Array]:
        """Per-step ``t, x, x_ref, xd, xd_ref, theta, theta_ref, thetad, psi, psi_ref``,
        ``torque`` (applied), ``clip_excess`` (N m by which the action exceeded its bounds),
        ``joint_deviation`` (rad), ``compute_time``."""
        return self._recorder.as_arrays()
