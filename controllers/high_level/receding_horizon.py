"""The high-level controller (docs/DESIGN.md §3): the offline plan at reset, MPC every ``mpc_dt``,
and what the low level reads between two MPC steps.

Between MPC steps the low level tracks the *current MPC solution's* predicted ``theta`` and
``thetad``, interpolated linearly inside the 10 ms, with the MPC's ``thdd`` as feed-forward;
the offline plan is only the MPC's reference, so the low level never fights a re-plan.

At every MPC step the robot's WIPM state and ``lambda(q)`` come from one compiled call
(``RobotModel.wipm_inputs``), written into the MPC's packed inputs
(``ModelPredictiveController.inputs_from``).

With ``mpc_delay_steps = d > 0`` the MPC runs as on a robot whose MPC computes beside its
control loop: the solve from the state at step ``k`` (its inputs packed at step ``k`` on the
control thread) runs in a background thread
(``controllers.high_level.solve_thread``: the thread runs the compiled step alone, which
releases the GIL; so do the control loop's compiled calls and ``mj_step``, where the thread
takes it to start the solve and to hand back its result), and its solution is taken
(``ModelPredictiveController.take``, on the control thread) and applied from step ``k + d``
on; until then the low level follows the previous solution further along its prediction.
Step ``k + d`` waits for the solve if it is not done, so an episode is the same whatever the
machine's speed (deterministic), and the control step's worst case no longer holds a whole MPC
solve. ``d = 0`` (the default, the paper's timing) solves in the
control step that uses it.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from controllers.high_level.mpc import (
    HOST_HEAD,
    ModelPredictiveController,
    MPCConfig,
    MPCStep,
    params_from_vector,
)
from controllers.high_level.planning import Plan, PlanConfig, plan_to_goal
from controllers.high_level.solve_thread import SolveThread
from controllers.simplified.wipm import WIPMParams
from wip_gym.minimal_kernels import WIPM_VECTOR_LENGTH
from wip_gym.robot_model import RobotModel


@dataclass(frozen=True)
class HighLevelConfig:
    """Plan and MPC settings (see :class:`PlanConfig`, :class:`MPCConfig`).

    Attributes:
        mpc_delay_steps: control steps between the state an MPC solve starts from and the
            first step that uses its solution (module docstring); 0 (the paper's timing, our
            default): the same step. Less than the MPC period in control steps.
    """

    plan: PlanConfig = field(default_factory=PlanConfig)
    mpc: MPCConfig = field(default_factory=MPCConfig)
    mpc_delay_steps: int = 0


#: the name of the MPC's thread beside the loop
MPC_THREAD = "wip-gym-mpc"


class _Finished(NamedTuple):
    """A solve's outputs already taken from its thread (a pickled pending solve): its
    ``result()`` is them."""

    outputs: Any

    def result(self) -> Any:
        return self.outputs


class _Failed(NamedTuple):
    """A solve's error already taken from its thread (a pickled pending solve that failed):
    its ``result()`` raises it."""

    error: Exception

    def result(self) -> Any:
        raise self.error


class HighLevelSetpoint(NamedTuple):
    """What the low level tracks at one control step (a NamedTuple: one is made every control
    step, 4 times cheaper than a frozen dataclass)."""

    theta: float
    thetad: float
    thdd: float
    tau_0: float
    mpc_index: int
    psi: float = 0.0
    psid: float = 0.0
    psidd: float = 0.0


class HighLevel:
    """Offline DDP plan + MPC on the WIPM for one robot (see the module docstring)."""

    def __init__(self, config: HighLevelConfig, control_dt: float) -> None:
        self.config = config
        ratio = config.mpc.dt / control_dt
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError(
                f"mpc dt {config.mpc.dt} is not a whole number of control steps of {control_dt}"
            )
        self.steps_per_mpc = int(round(ratio))
        if not 0 <= config.mpc_delay_steps < self.steps_per_mpc:
            raise ValueError(
                f"mpc_delay_steps must be in [0, {self.steps_per_mpc}) (the MPC period in "
                f"control steps), got {config.mpc_delay_steps}"
            )
        self.control_dt = control_dt
        self.plan: Plan | None = None
        self.mpc: ModelPredictiveController | None = None
        self._last: MPCStep | None = None
        self._last_start = 0  # the control step whose state self._last was solved from
        # the rows of self._last's prediction that reference() interpolates, as Python floats
        # (the solution in use is at most one MPC step along its prediction): made once per
        # solution, not read as NumPy scalars every control step
        self._rows_used = (
            2 + (self.steps_per_mpc - 1 + config.mpc_delay_steps) // self.steps_per_mpc
        )
        self._last_rows: tuple[list[list[float]], list[list[float]]] = ([], [])
        # a solve beside the loop not taken yet: (its source, the step it started from); the
        # source's result() is the compiled step's outputs (the thread, or _Finished after a
        # pickle)
        self._pending: tuple[SolveThread | _Finished | _Failed, int] | None = None
        self._thread: SolveThread | None = None
        self._params: WIPMParams | None = None
        self._wipm_inputs: np.ndarray | None = None  # the last MPC step's, params made from it
        self._rejections = 0
        if config.mpc_delay_steps > 0 and config.mpc.steps < 2:
            raise ValueError(
                "a delayed MPC reads its prediction one MPC step further: its horizon must hold "
                f"at least 2 steps, got {config.mpc.steps}"
            )

    def _discard_pending(self) -> None:
        """Wait for a background solve and drop it (its episode is over); also a job left in
        the thread by a wait that was interrupted (``KeyboardInterrupt``)."""
        sources = [] if self._pending is None else [self._pending[0]]
        if self._thread is not None and self._thread.running and self._thread not in sources:
            sources.append(self._thread)
        self._pending = None
        for source in sources:
            # waits; an error of a finished episode's solve is not raised
            with contextlib.suppress(Exception):
                source.result()

    def __getstate__(self) -> dict[str, object]:
        state = self.__dict__.copy()
        state["_thread"] = None  # threads do not pickle; made again when needed
        if self._pending is not None:  # its outputs, kept to be taken at the same step
            source, start = self._pending
            if isinstance(source, SolveThread):
                finished: _Finished | _Failed
                try:
                    finished = _Finished(source.result())
                except Exception as error:  # kept, to be raised where it would have been
                    finished = _Failed(error)
                self._pending = (finished, start)
            state["_pending"] = self._pending
        return state

    def _solve_later(self, host: np.ndarray) -> None:
        """Start the MPC step of the packed inputs ``host`` in the MPC's thread."""
        if self._thread is None:
            self._thread = SolveThread(name=MPC_THREAD)
        assert self.mpc is not None
        self._thread.submit(self.mpc.run, host)
        self._pending = (self._thread, self._step)

    def _wait_pending(self) -> None:
        """Take the pending solve's solution (waiting for it) as the one in use."""
        if self._pending is not None:
            source, start = self._pending
            try:
                outputs = source.result()
            except Exception:  # the solve's own error: it is over
                self._pending = None
                raise
            # (a wait interrupted by KeyboardInterrupt keeps the solve pending)
            self._pending = None
            assert self.mpc is not None
            self._use(self.mpc.take(outputs), start)

    def _use(self, solution: MPCStep, start: int) -> None:
        """``solution``, solved from step ``start``'s state, in use from now on (counted on the
        control thread: the counters do not depend on the background thread's timing)."""
        self._last, self._last_start = solution, start
        rows = self._rows_used
        self._last_rows = (
            solution.predicted_states[:rows].tolist(),
            solution.predicted_controls[: rows - 1].tolist(),
        )
        self._rejections += not solution.accepted

    def reset(self, robot: RobotModel, goal_xy: np.ndarray, cup_friction: float | None) -> Plan:
        """Plan from the robot's current state to the goal, build the MPC and run (and so
        compile) its first step. ``robot`` must be updated."""
        self._discard_pending()  # a solve still running from the last episode
        # the MPC steps' path, so that its compiled calls are loaded here, not at a step
        inputs = robot.wipm_inputs()
        n = len(inputs) - WIPM_VECTOR_LENGTH
        params = params_from_vector(inputs[n:].copy())
        plan = plan_to_goal(
            inputs[:n].copy(),
            params,
            goal_xy,
            planar=robot.layout.planar,
            cup_friction=cup_friction,
            config=self.config.plan,
        )
        # one solve now compiles the MPC (reset does the slow work); then start afresh
        first = ModelPredictiveController(plan, self.config.mpc)
        first.solve(first.inputs_from(0, robot))
        self.plan, self._wipm_inputs, self._params = plan, inputs, params
        self.mpc = ModelPredictiveController(self.plan, self.config.mpc)
        self._step = 0
        self._last = None
        self._rejections = 0
        return self.plan

    def reference(self, robot: RobotModel) -> HighLevelSetpoint:
        """Advance one control step: run the MPC when it is due (``lambda(q)`` from the robot's
        current state), and return the references interpolated inside the MPC step."""
        if self.mpc is None or self.plan is None:
            raise RuntimeError("HighLevel.reset() first")
        step, steps_per_mpc = self._step, self.steps_per_mpc
        index, phase = divmod(step, steps_per_mpc)
        delay = self.config.mpc_delay_steps
        if phase == 0 or self._last is None:
            # the state and lambda(q) in one compiled call, written into the packed inputs
            host = self.mpc.inputs_from(index, robot)
            self._wipm_inputs, self._params = host[HOST_HEAD:], None
            if delay == 0 or self._last is None:
                self._use(self.mpc.solve(host), step)
            else:
                self._solve_later(host)
        pending = self._pending
        if pending is not None and step >= pending[1] + delay:
            self._wait_pending()
        assert self._last is not None
        # where the solution in use is along its own prediction (inside its first MPC step
        # unless it is delayed); its rows as Python floats (_use): the same arithmetic as on
        # the solution's float64 arrays (in float64 even if JAX ran without jax_setup's x64)
        interval, rest = divmod(step - self._last_start, steps_per_mpc)
        self._step = step + 1
        fraction = rest / steps_per_mpc
        states, controls = self._last_rows
        s0, s1 = states[interval], states[interval + 1]
        control = controls[interval]
        # positional: a NamedTuple made from keywords costs twice as much, every control step
        if robot.layout.planar:
            return HighLevelSetpoint(
                (1 - fraction) * s0[0] + fraction * s1[0],  # theta
                (1 - fraction) * s0[1] + fraction * s1[1],  # thetad
                control[0],  # thdd
                0.0,  # tau_0
                index,  # mpc_index
            )
        return HighLevelSetpoint(
            (1 - fraction) * s0[2] + fraction * s1[2],  # theta
            (1 - fraction) * s0[5] + fraction * s1[5],  # thetad
            control[0],  # thdd
            control[1],  # tau_0
            index,  # mpc_index
            (1 - fraction) * s0[1] + fraction * s1[1],  # psi
            (1 - fraction) * s0[4] + fraction * s1[4],  # psid
            (s1[4] - s0[4]) / self.config.mpc.dt,  # psidd
        )

    @property
    def params(self) -> WIPMParams:
        """``lambda(q)`` of the latest MPC step started (at reset: the plan's), made from its
        inputs at the first read after that step (the same floats as ``params_from_robot``).
        Read-only (it was a plain attribute before the MPC read its inputs in one compiled
        call). ``RuntimeError`` before :meth:`reset`."""
        if self._params is None:
            if self._wipm_inputs is None:
                raise RuntimeError("HighLevel.reset() first")
            lam = self._wipm_inputs[len(self._wipm_inputs) - WIPM_VECTOR_LENGTH :]
            self._params = params_from_vector(lam.copy())
        return self._params

    @property
    def last_solution(self) -> MPCStep:
        """The latest MPC solution (``RuntimeError`` before the first ``reference``)."""
        if self._last is None:
            raise RuntimeError("HighLevel.reference() first")
        return self._last

    @property
    def rejections(self) -> int:
        """The MPC solutions rejected since ``reset`` (0 before it), counted when a solution is
        taken into use (a solve still running in the background is not counted yet)."""
        return self._rejections

    def close(self) -> None:
        """Let a background solve end (taken into use; its error raised) and stop the MPC's
        thread (made again if needed)."""
        try:
            self._wait_pending()
        finally:
            if self._thread is not None:
                self._thread.close()  # a job still running (an interrupted wait) is dropped
                if self._pending is not None and self._pending[0] is self._thread:
                    self._pending = None
                self._thread = None
