"""Model predictive control on the WIPM, tracking the offline plan (paper section "Receding
Horizon Control"; issue 4).

Every ``dt`` (10 ms) over ``horizon_s`` (the paper's 1 s; the authors' code used 0.1 s), from
the current WIPM state with ``lambda(q)`` updated at every step (as the paper says; the
authors' code froze it), the DDP tracks the plan's window by time index (padded with the goal
state past the plan's end), warm-started from the previous solution shifted by one step, with a
fixed budget of iterations (real-time MPC does not wait for convergence). Its result is used
when it is finite and its cost did not rise above the warm start's; otherwise (a NaN or a
divergence) the previous controls, shifted, are kept and the rejection is counted.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import jax
import numpy as np

from controllers.ddp import DDPConfig, rollout
from controllers.planning import Plan
from controllers.wipm import WIPMParams
from controllers.wipm_problem import Weights, WIPMProblem, ddp_solver_for, refs_for


@dataclass(frozen=True)
class MPCConfig:
    """MPC settings; the authors' values (krang_facts 3.3) for comparison.

    Attributes:
        horizon_s, dt: 1 s at 10 ms (paper: 1 s; authors' code: 10 steps = 0.1 s at 10 ms).
        iterations: DDP iterations per MPC step (authors: 50; real-time budget here: 2).
        q_theta, q_thetad, q_position, q_speed, q_heading: tracking weights (authors' 3-D
            Q = diag[0, 10, 10, 0.1, 0.1, 0.1, 10, 10] over [x, psi, theta, xd, psid, thetad,
            X0, Y0]: higher on positions than speeds, as the paper says).
        r_control: weights on [thdd, tau_0] (authors 0.01, 0.01).
        q_terminal: terminal weights on positions and theta (authors 1e5) and speeds (1e4).
        q_terminal_speed: see above.
        ddp: solver settings except the iteration budget (iLQR, no tolerance stop).
    """

    horizon_s: float = 1.0
    dt: float = 0.01
    iterations: int = 2
    q_theta: float = 10.0
    q_thetad: float = 0.1
    q_position: float = 10.0
    q_speed: float = 0.1
    q_heading: float = 10.0
    r_control: float = 0.01
    q_terminal: float = 1e5
    q_terminal_speed: float = 1e4
    ddp: DDPConfig = field(
        default_factory=lambda: DDPConfig(max_iterations=2, tolerance=0.0, second_order=False)
    )

    @property
    def steps(self) -> int:
        steps = self.horizon_s / self.dt
        if abs(steps - round(steps)) > 1e-9 or steps < 1:
            raise ValueError(f"MPC horizon {self.horizon_s} s is not a whole number of {self.dt} s")
        return int(round(steps))


def mpc_problem(planar: bool, config: MPCConfig, a_max: float, theta_max: float) -> WIPMProblem:
    c = config
    if planar:
        q = (c.q_theta, c.q_thetad, c.q_position, c.q_speed)
        q_terminal = (c.q_terminal, c.q_terminal_speed, c.q_terminal, c.q_terminal_speed)
        r = (c.r_control,)
    else:
        q = (0.0, c.q_heading, c.q_theta, c.q_speed, c.q_speed, c.q_thetad, c.q_position,
             c.q_position)  # fmt: skip
        q_terminal = (0.0, c.q_terminal, c.q_terminal, c.q_terminal_speed, c.q_terminal_speed,
                      c.q_terminal_speed, c.q_terminal, c.q_terminal)  # fmt: skip
        r = (c.r_control, c.r_control)
    weights = Weights(q=q, r=r, r_rate=(), q_terminal=q_terminal, a_max=a_max,
                      theta_max=theta_max)  # fmt: skip
    return WIPMProblem(planar=planar, dt=c.dt, weights=weights, rate_input=False)


@dataclass(frozen=True)
class MPCStep:
    """One MPC solution: the control to apply now, the predicted trajectory, and whether the
    new solution was accepted."""

    control: np.ndarray
    predicted_states: np.ndarray
    predicted_controls: np.ndarray
    cost: float
    accepted: bool


class ModelPredictiveController:
    """Receding-horizon DDP tracking a :class:`Plan` (see the module docstring)."""

    def __init__(self, plan: Plan, config: MPCConfig | None = None) -> None:
        self.config = config or MPCConfig()
        if abs(self.config.dt - plan.dt) > 1e-12:
            raise ValueError(f"MPC dt {self.config.dt} differs from the plan's {plan.dt}")
        self.plan = plan
        self.problem = mpc_problem(plan.planar, self.config, plan.a_max, plan.theta_max)
        ddp = DDPConfig(**{**self.config.ddp.__dict__, "max_iterations": self.config.iterations})
        self.solver = ddp_solver_for(self.problem, ddp)
        self._rollout = jax.jit(functools.partial(rollout, self.problem.dynamics()))
        self.horizon = self.config.steps
        self.rejected = 0
        self.solves = 0
        self._controls: np.ndarray | None = None  # first step: the plan's controls

    def step(self, index: int, state: np.ndarray, params: WIPMParams) -> MPCStep:
        """Solve at plan time index ``index`` from WIPM ``state`` with parameters ``params``."""
        state = np.asarray(state, dtype=float)
        if not np.all(np.isfinite(state)):
            raise ValueError(f"MPC state is not finite: {state}")
        refs = refs_for(self.plan.window(index, self.horizon + 1), params)
        warm = (
            self._controls
            if self._controls is not None
            else self.plan.control_window(index, self.horizon)
        )
        result = self.solver(state, warm, params, refs)
        self.solves += 1
        X, U = np.asarray(result.X), np.asarray(result.U)
        cost = float(result.cost)
        initial = float(result.cost_history[0])
        accepted = bool(np.all(np.isfinite(X)) and np.all(np.isfinite(U)) and np.isfinite(cost)
                        and cost <= initial * (1 + 1e-12) + 1e-12)  # fmt: skip
        if not accepted:
            self.rejected += 1
            U = warm
            X = np.asarray(self._rollout(state, U, params))
            cost = initial
        # warm start of the next step: shifted by one, the plan's control past the end
        self._controls = np.vstack([U[1:], self.plan.control_window(index + self.horizon, 1)])
        return MPCStep(control=U[0].copy(), predicted_states=X, predicted_controls=U, cost=cost,
                       accepted=accepted)  # fmt: skip
