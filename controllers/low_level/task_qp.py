"""The whole-body task QP on the isolated manipulator dynamics, solved by ProxQP.

Decision variable ``qdd`` (every minimal acceleration but ``xdd``). Cost
``0.5 ||T qdd - b||^2 + 0.5 eps ||qdd||^2`` stacked from weighted tasks
(``controllers.low_level.tasks``; ``T`` is the paper's task matrix, renamed: ``P`` is eq.
``iso3``'s, docs/ERRATA.md §2). Constraints:

* every actuator's torque within its limits, ``tau_min <= M_act (calA qdd + P h) <= tau_max``,
  where ``M_act`` maps ``Gamma`` to the actuators: the wheels through the tested
  ``(tau_0, tau_1) -> (tau_L, tau_R)`` map (box limits on ``tau_0``, ``tau_1`` would not bound
  the wheels), the joints one to one. Nothing is left for MuJoCo to clip.
* joint position limits as acceleration bounds that stop each limited joint inside its range
  within ``limit_horizon`` s: ``2 (q_min - q - qd h) / h^2 <= qdd <= 2 (q_max - q - qd h) / h^2``.
* the caller's extra constraints (``controllers.low_level.constraints``): ``lower <= G nu_dot +
  Jdot nu <= upper``.

One dense ProxQP object per controller, reused and warm-started step to step; its status is
checked every step, and an unsolved QP falls back to the last feasible torques (counted).
Before ProxQP, each step tries the minimiser without constraints, ``H qdd = -g``: when it
satisfies every constraint it is the QP's exact optimum (the QP is convex and its constraints
are then inactive), and ProxQP is not called. In closed loop that is most steps; ProxQP,
warm-started, takes the others (``proxqp_calls`` counts them).

Two paths fill the QP (docs/DESIGN.md §3), held equal by the tests:

* **compiled**: with every task and constraint of a compiled kind, eq. ``iso3`` from the robot
  and the robot on the fast path (``wip_gym.mujoco_c``), the rows, the kernel and the torques of
  a feasible minimiser are one compiled call (``controllers.low_level.compiled_step``) on the
  table of a ``CompiledTaskStack``, which copies the objects' parameters in at every step;
* **readable**: otherwise (``QPSettings.compiled_tasks`` False, a task of a new kind, a given
  ``iso``, the readable robot path), each object gives its rows (``jacobian``,
  ``reference_acceleration``, ``weights``, ``jdot_nu``; a constraint its ``bounds``) and the
  kernel (``controllers.low_level.kernel``) runs on them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
import proxsuite
from numpy.typing import NDArray

from controllers.low_level.isolated_dynamics import IsolatedDynamics
from controllers.low_level.kernel import KernelLayout, LowLevelKernel, solution_terms
from controllers.low_level.motion_probe import MotionProbe
from controllers.low_level.qp_solver import QPSettings, start_proxqp
from controllers.low_level.task_stack import (
    CompiledTaskStack,
    check_indices,
    rows_of,
    supports,
    unwrap,
)
from wip_gym.robot_model import RobotModel
from wip_gym.wheel_torques import generalized_to_wheel_matrix

Array = NDArray[np.float64]
_SOLVED = proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED


class QPSolution(NamedTuple):
    """The task QP's answer at one step (a NamedTuple: one is made every control step)."""

    qdd: Array
    nu_dot: Array
    generalized: Array
    actuators: Array
    solved: bool
    iterations: int


def actuator_map(robot: RobotModel) -> Array:
    """``M_act`` with ``actuator torques = M_act Gamma`` (``Gamma`` over ``q``: 3-D
    ``[tau_0, tau_1, joints]``, planar ``[tau_1, joints]``)."""
    lay = robot.layout
    k = lay.index_q1 - 1
    M = np.zeros((robot.model.nu, lay.n_min - 1))
    wl, wr = lay.wheel_actuators
    if lay.planar:
        M[wl, k] = M[wr, k] = -0.5  # tau_L = tau_R = -tau_1 / 2
    else:
        W = generalized_to_wheel_matrix(lay.wheel_radius, lay.wheel_separation)
        M[[wl, wr], 0] = W[:, 0]
        M[[wl, wr], k] = W[:, 1]
    for j, actuator in enumerate(lay.joint_actuators):
        M[actuator, k + 1 + j] = 1.0
    return M


class TaskQP:
    """Assemble and solve the task QP for one robot (see the module docstring)."""

    def __init__(
        self, robot: RobotModel, torque_low: Array, torque_high: Array, settings: QPSettings
    ) -> None:
        self.settings = settings
        self.torque_low = np.asarray(torque_low, dtype=float)
        self.torque_high = np.asarray(torque_high, dtype=float)
        self.M_act = actuator_map(robot)
        lay, m = robot.layout, robot.model
        limited = np.array(
            [
                (lay.index_q1 + j, lay.index_q1 + 1 + j, *m.jnt_range[m.dof_jntid[dof]])
                for j, dof in enumerate(lay.body_dof)
                if m.jnt_limited[m.dof_jntid[dof]]
            ]
        ).reshape(-1, 4)  # the joint-limit rows: qdd column, minimal index, range
        # the kernel's constants (its row counts and torque-limit arrays set when it is made)
        self._layout = KernelLayout(
            n_min=lay.n_min,
            index_q1=lay.index_q1 - 1,
            wheel_radius=float(lay.wheel_radius),
            actuator_map=self.M_act,
            torque_low=self.torque_low,
            torque_high=self.torque_high,
            limit_columns=limited[:, 0].astype(int),
            limit_indices=limited[:, 1].astype(int),
            limit_min=limited[:, 2].copy(),
            limit_max=limited[:, 3].copy(),
            limit_horizon=settings.limit_horizon,
            regularization=settings.regularization,
            rows=0,
        )
        self.n = lay.n_min - 1
        self._qp: proxsuite.proxqp.dense.QP | None = None
        # whether ProxQP solved a step since the start or its last failure: only then is the
        # unconstrained minimiser tried first (the first step, and the one after a failure,
        # go to ProxQP)
        self._proxqp_ready = False
        self.failures = 0
        self.proxqp_calls = 0
        self.motion = MotionProbe(robot)
        self._last_actuators: Array | None = None
        self.kernel: LowLevelKernel | None = None  # made for the rows of the first step
        self._stack: CompiledTaskStack | None = None
        self._feasible = False
        self._terms_ready = False  # the compiled call computed what the minimiser implies
        self.compiled = False  # whether the last step took the compiled path

    def _kernel_for(self, rows: int, constraint_rows: int) -> LowLevelKernel:
        """The kernel for these row counts and the current torque-limit arrays (made anew
        when any differs)."""
        k = self.kernel
        if (
            k is None
            or (k.layout.rows, k.layout.constraint_rows) != (rows, constraint_rows)
            or k.layout.torque_low is not self.torque_low
            or k.layout.torque_high is not self.torque_high
        ):
            k = self.kernel = LowLevelKernel(
                dataclasses.replace(
                    self._layout,
                    torque_low=self.torque_low,
                    torque_high=self.torque_high,
                    rows=rows,
                    constraint_rows=constraint_rows,
                )
            )
        return k

    def _compiled_stack(
        self, robot: RobotModel, tasks: Sequence[Any], constraints: Sequence[Any]
    ) -> CompiledTaskStack | None:
        """The compiled stack of these lists (made when they, the robot or the kernel changed),
        or None when the settings, the robot or a task's kind ask for the readable path."""
        stack, kernel = self._stack, self.kernel
        if (
            stack is not None
            and kernel is not None
            and kernel.layout.torque_low is self.torque_low
            and kernel.layout.torque_high is self.torque_high
            and stack.serves(robot, kernel, tasks, constraints)
        ):
            return stack
        if not (
            self.settings.compiled_tasks
            and robot.fast_path
            and supports(tasks, constraints, robot.layout.planar)
        ):
            return None
        check_indices([*tasks, *constraints], robot.model.nsite, robot.layout.n_min)
        kernel = self._kernel_for(
            sum(rows_of(unwrap(task)[0]) for task in tasks), sum(map(rows_of, constraints))
        )
        self._stack = CompiledTaskStack(robot, self.motion, kernel, tasks, constraints)
        return self._stack

    def __getstate__(self) -> dict[str, object]:
        state = self.__dict__.copy()
        state["_stack"] = None  # holds views on MuJoCo's arrays: made again on the next step
        # ProxQP's object pickles as an empty C++ object, which crashes the process at its
        # next update (and a deep copy is a pickle): a copy starts a new one at its next
        # ProxQP solve, not warm-started from the original's last result (so that solve
        # agrees with the original's to ProxQP's tolerance, not to the bit)
        state["_qp"] = None
        return state

    def _readable_rows(
        self, robot: RobotModel, tasks: Sequence[Any], constraints: Sequence[Any]
    ) -> LowLevelKernel:
        """The readable path's rows, object by object, into the kernel's row buffers."""
        # MuJoCo's Jacobian calls read past their arrays on a bad site id (a negative one
        # would pass NumPy's indexing): the same checks as a compiled stack's
        check_indices([*tasks, *constraints], robot.model.nsite, robot.layout.n_min)
        n = len(tasks)
        blocks = [item.jacobian(robot) for item in (*tasks, *constraints)]
        k = self._kernel_for(sum(map(len, blocks[:n])), sum(map(len, blocks[n:])))
        self.motion.update(robot)
        start = 0
        for task, block in zip(tasks, blocks[:n], strict=True):
            rows, start = slice(start, start + len(block)), start + len(block)
            k.J[rows], k.target[rows] = block, task.reference_acceleration(robot)
            k.w[rows], k.jdot_nu[rows] = task.weights(), self._drift(task)
        start = 0
        for constraint, block in zip(constraints, blocks[n:], strict=True):
            rows, start = slice(start, start + len(block)), start + len(block)
            k.G[rows], k.constraint_bias[rows] = block, self._drift(constraint)
            k.constraint_lower[rows], k.constraint_upper[rows] = constraint.bounds(robot)
        return k

    def jdot_nu(self, robot: RobotModel, items: Sequence[Any]) -> Array:
        """``Jdot nu`` of the tasks' (or constraints') rows, stacked: d/dt of ``J(q) nu`` at
        fixed ``nu``, exact from each one's ``jdot_nu(probe)`` at the robot's state."""
        self.motion.update(robot)
        return np.concatenate([self._drift(item) for item in items] or [np.zeros(0)])

    def _drift(self, item: Any) -> Array:
        """An object's ``jdot_nu`` from the motion probe (updated at this state)."""
        if not hasattr(item, "jdot_nu"):
            raise ValueError(
                f"task {getattr(item, 'name', item)!r} has no jdot_nu(probe): "
                "every task of the QP needs its exact Jdot nu"
            )
        return np.asarray(item.jdot_nu(self.motion))

    def _run_kernel(
        self,
        robot: RobotModel,
        iso: IsolatedDynamics | None,
        tasks: Sequence[Any],
        constraints: Sequence[Any] = (),
    ) -> bool:
        """This state's rows, ``H``, ``g``, constraint rows and unconstrained minimiser into
        the kernel's buffers, by the path that applies; whether the minimiser is feasible
        (``wip-bench profile`` times it as ``qp_assembly``)."""
        if iso is None and not robot.has_dynamics:
            raise RuntimeError("the last robot update had dynamics=False: no A, h")
        stack = self._compiled_stack(robot, tasks, constraints) if iso is None else None
        self.compiled = stack is not None
        if stack is not None:
            self._terms_ready = feasible = stack.step(robot)
            return feasible
        self._terms_ready = False
        k = self._readable_rows(robot, tasks, constraints)
        A, h = (robot.A, robot.h) if iso is None else (None, None)
        extra = (k.G, k.constraint_lower, k.constraint_bias, k.constraint_upper)
        return k.run(A, h, k.J, k.target, k.jdot_nu, k.w, robot.q, robot.nu, iso, extra)

    def task_rows(
        self, robot: RobotModel, iso: IsolatedDynamics | None, tasks: Sequence[Any]
    ) -> tuple[Array, Array]:
        """``T`` and ``b`` of the stacked weighted tasks (the kernel's buffers: overwritten by
        the next call, copy to keep). ``iso`` None: eq. iso3 from ``robot`` in the kernel."""
        self._run_kernel(robot, iso, tasks)
        return self.kernel.T, self.kernel.b  # type: ignore[union-attr]

    def assemble(
        self,
        robot: RobotModel,
        iso: IsolatedDynamics | None,
        tasks: Sequence[Any],
        constraints: Sequence[Any] = (),
    ) -> tuple[Array, Array, Array, Array, Array]:
        """The QP ``min 0.5 qdd' H qdd + g' qdd  s.t.  lower <= C qdd <= upper`` of this state,
        as ``(H, g, C, lower, upper)`` (what ``solve`` hands ProxQP; the benchmark's peers
        solve the same arrays). They are the kernel's buffers, overwritten by the next call:
        copy to keep. ``iso`` None: eq. iso3 in the kernel."""
        self._feasible = self._run_kernel(robot, iso, tasks, constraints)
        k = self.kernel
        return k.H, k.g, k.C, k.lower, k.upper  # type: ignore[union-attr]

    def solve(
        self,
        robot: RobotModel,
        iso: IsolatedDynamics | None,
        tasks: Sequence[Any],
        constraints: Sequence[Any] = (),
    ) -> QPSolution:
        """The task QP of this state (``iso`` None: eq. iso3 computed in the kernel from
        ``robot``). ``proxqp_calls`` counts the steps ProxQP solved."""
        H, g, C, lower, upper = self.assemble(robot, iso, tasks, constraints)
        if (shortcut := self.shortcut()) is not None:
            return shortcut
        self.proxqp_calls += 1
        if self._qp is None or self._qp.model.n_in != len(C):
            self._qp = start_proxqp(H, g, C, lower, upper, self.settings)
        else:
            self._qp.update(H=H, g=g, C=C, l=lower, u=upper)
            self._qp.solve()
        results = self._qp.results
        iterations = int(results.info.iter)
        if results.info.status == _SOLVED and bool(np.all(np.isfinite(results.x))):
            self.note_solved()
            return self.solution_for(np.array(results.x), iterations)
        self._qp = None  # start the next step cold: a failed result is no warm start
        return self.fallback(iterations)

    def shortcut(self) -> QPSolution | None:
        """The last assembled QP's feasible unconstrained minimiser if it may be taken."""
        if not (self.ready_for_shortcut and self._feasible):
            return None
        k: LowLevelKernel = self.kernel  # type: ignore[assignment]
        if self._terms_ready:  # the compiled call computed what x implies
            self._last_actuators = actuators = k.actuators.copy()
            return QPSolution(k.x.copy(), k.nu_dot.copy(), k.generalized.copy(), actuators, True, 0)
        return self.solution_for(k.x.copy(), iterations=0)

    @property
    def ready_for_shortcut(self) -> bool:
        """Whether a feasible unconstrained minimiser may be taken without ProxQP: the
        settings allow it and a QP was solved since the start or the last failure."""
        return self._proxqp_ready and self.settings.unconstrained_first

    def note_solved(self) -> None:
        """A QP of this controller was solved (by ProxQP or by a caller's solver)."""
        self._proxqp_ready = True

    def fallback(self, iterations: int) -> QPSolution:
        """The answer to an unsolved QP: the last feasible torques (counted in ``failures``),
        NaN accelerations; the next step goes to the solver. RuntimeError before any."""
        self.failures += 1
        self._proxqp_ready = False
        if self._last_actuators is None:
            raise RuntimeError("the first task QP was not solved: no feasible torques yet")
        nan = np.full(self.n, np.nan)
        return QPSolution(
            nan, np.full(self.n + 1, np.nan), nan.copy(), self._last_actuators, False, iterations
        )

    def solution_for(self, qdd: Array, iterations: int) -> QPSolution:
        """The solved QP's answer for ``qdd``, with its ``(generalized, actuators, nu_dot)``
        (``kernel.solution_terms``; the compiled call computes them itself when the
        unconstrained minimiser is the answer)."""
        k: LowLevelKernel = self.kernel  # type: ignore[assignment]
        generalized, actuators, nu_dot = solution_terms(k.calA, k.Ph, self.M_act, k.E, k.e, qdd)
        self._last_actuators = actuators
        return QPSolution(qdd, nu_dot, generalized, actuators, True, iterations)
