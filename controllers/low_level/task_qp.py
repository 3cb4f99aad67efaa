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

One dense ProxQP object per controller, reused and warm-started step to step; its status is
checked every step, and an unsolved QP falls back to the last feasible torques (counted).
Before ProxQP, each step tries the minimiser without constraints, ``H qdd = -g`` (one LAPACK
Cholesky solve, ``dposv``): when it satisfies every constraint it is the QP's exact optimum (the
QP is convex and its constraints are then inactive), and ProxQP is not called. In closed loop
that is most steps (no torque or joint limit active); ProxQP, warm-started, takes the others
(``proxqp_calls`` counts them).

Per step: the tasks fill the stacked rows (``J``, ``xdd*``, ``Jdot nu``, ``w``); then the kernel
(``controllers.low_level.kernel``) computes eq. ``iso3`` (unless the caller passes it), ``T``,
``b``, ``H``, ``g``, the constraint rows and the unconstrained minimiser with its feasibility.
With the compiled rows and eq. ``iso3`` from the robot (the controller's case), both and the
torques of a feasible minimiser are one compiled call (``controllers.low_level.compiled_step``,
``QPSettings.one_call``); otherwise the rows (compiled or task by task) and the kernel are two.
Weights are per row, so a task may weight each of its rows differently (per axis, per joint).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import proxsuite
from numpy.typing import NDArray
from scipy.linalg.lapack import dposv

from controllers.low_level.compiled_step import rows_and_kernel, step_table
from controllers.low_level.isolated_dynamics import IsolatedDynamics
from controllers.low_level.kernel import KernelLayout, LowLevelKernel, solution_terms
from controllers.low_level.motion_probe import MotionProbe
from controllers.low_level.task_stack import CompiledTaskStack, check_indices, supports
from controllers.low_level.tasks import Task
from wip_gym.array_table import ArrayTable
from wip_gym.robot_model import RobotModel
from wip_gym.wheel_torques import generalized_to_wheel_matrix

Array = NDArray[np.float64]
_SOLVED = proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED


@dataclass(frozen=True)
class QPSettings:
    """Attributes:
    regularization: ``eps`` on ``||qdd||^2`` (keeps the Hessian positive definite).
    eps_abs: ProxQP's absolute tolerance. Its default (1e-5 on the KKT residual) can stop
        with constraint errors of order 1e-3 N m here; 1e-9 gives answers that are right.
    limit_horizon: ``h`` of the joint-limit acceleration bounds (s).
    max_iterations: ProxQP's iteration cap (its default, 10000, lets an infeasible QP run for
        a minute before it gives up; a feasible one here takes under 20).
    unconstrained_first: try the unconstrained minimiser before ProxQP (module docstring).
    compiled_tasks: fill the task rows by one compiled call
        (``controllers.low_level.task_stack``) when every task is of a kind it knows; False:
        always from the task objects (the reference it is tested against).
    one_call: with compiled rows and eq. ``iso3`` from the robot, the rows and the kernel as
        one compiled call whose arrays come from one table
        (``controllers.low_level.compiled_step``; the same arithmetic, tested equal to the
        bit); False: the rows' call then the kernel's.
    """

    regularization: float = 1e-6
    eps_abs: float = 1e-9
    limit_horizon: float = 0.05
    max_iterations: int = 1000
    unconstrained_first: bool = True
    compiled_tasks: bool = True
    one_call: bool = True


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
    n_q = lay.n_min - 1
    k = lay.index_q1 - 1
    M = np.zeros((robot.model.nu, n_q))
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


def feasible_unconstrained_minimiser(
    H: Array, g: Array, C: Array, lower: Array, upper: Array
) -> Array | None:
    """``x = -H^-1 g`` (one LAPACK Cholesky solve; ``H`` is symmetric positive definite, being
    regularised) when it meets every constraint: then it is the convex QP's exact optimum.
    None otherwise (the QP needs a solver)."""
    _, x, info = dposv(H, -g)
    if info != 0 or not np.isfinite(x).all():
        return None
    Cx = C @ x
    return x if (Cx >= lower).all() and (Cx <= upper).all() else None


def start_proxqp(
    H: Array, g: Array, C: Array, lower: Array, upper: Array, settings: QPSettings
) -> proxsuite.proxqp.dense.QP:
    """A dense ProxQP object for this QP, configured as ``settings`` says, solved once, and
    set to warm start every later ``update`` + ``solve`` from the previous result."""
    qp = proxsuite.proxqp.dense.QP(len(g), 0, len(C))
    qp.settings.eps_abs = settings.eps_abs
    qp.settings.eps_rel = 0.0
    # no preconditioner: its scaling, computed once from the first H and kept by update(),
    # stalls badly conditioned task weightings (a weight-100 theta task alone never converged
    # with it)
    qp.settings.max_iter = settings.max_iterations
    qp.init(H, g, None, None, C, lower, upper, compute_preconditioner=False)
    qp.solve()
    # warm start only once a previous result exists (ProxQP 0.8 crashes otherwise)
    qp.settings.initial_guess = proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
    return qp


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
        k = lay.index_q1 - 1
        limited = []
        for j, dof in enumerate(lay.body_dof):
            joint = m.dof_jntid[dof]
            if m.jnt_limited[joint]:
                limited.append((k + 1 + j, lay.index_q1 + 1 + j, *m.jnt_range[joint]))
        self.n = lay.n_min - 1
        # the joint-limit rows, vectorised: qdd column, minimal index, range
        columns, indices, q_min, q_max = (
            (np.array(v) for v in zip(*limited, strict=True))
            if (limited)
            else (np.zeros(0, dtype=int), np.zeros(0, dtype=int), np.zeros(0), np.zeros(0))
        )
        self._limit_columns = columns.astype(int)
        self._limit_index = indices.astype(int)
        self._limit_min, self._limit_max = q_min.astype(float), q_max.astype(float)
        self._index_q1, self._wheel_radius = k, float(lay.wheel_radius)
        self._qp: proxsuite.proxqp.dense.QP | None = None
        # whether ProxQP solved a step since the start or its last failure: only then is the
        # unconstrained minimiser tried first (the first step, and the one after a failure,
        # go to ProxQP). Kept by a copy, which drops the solver object (__getstate__)
        self._proxqp_ready = False
        self.failures = 0
        self.proxqp_calls = 0
        self.motion = MotionProbe(robot)
        self._last_actuators: Array | None = None
        self._J: Array | None = None  # task-row buffers and kernel, made by _buffers
        self._rows = -1
        self._feasible = False
        self._terms_ready = False  # the kernel's solution terms are of this step's x
        self._stack: CompiledTaskStack | None = None
        # the one-call step's table and the (stack, kernel) it was built for
        self._table: ArrayTable | None = None
        self._table_for: tuple[object, object] = (None, None)
        # what the last full one-call step found, for the next step's cheap check (_steady)
        self._steady: tuple[Any, ...] | None = None
        self.compiled = False  # whether the last step's rows came from the compiled call

    def _buffers(self, rows: int, n_min: int) -> None:
        """(Re)allocate the task-row buffers and the kernel for ``rows`` rows (once per task
        set)."""
        self._rows = rows
        self._J = np.zeros((rows, n_min))
        self._target = np.zeros(rows)
        self._w = np.zeros(rows)
        self._bias = np.zeros(rows)
        self.kernel = LowLevelKernel(
            KernelLayout(
                n_min=n_min,
                index_q1=self._index_q1,
                wheel_radius=self._wheel_radius,
                actuator_map=self.M_act,
                torque_low=self.torque_low,
                torque_high=self.torque_high,
                limit_columns=self._limit_columns,
                limit_indices=self._limit_index,
                limit_min=self._limit_min,
                limit_max=self._limit_max,
                limit_horizon=self.settings.limit_horizon,
                regularization=self.settings.regularization,
                rows=rows,
            )
        )

    def _ensure_buffers(self, rows: int, n_min: int) -> None:
        J = self._J
        if (
            J is None
            or self._rows != rows
            or J.shape[1] != n_min
            or self.kernel.layout.torque_low is not self.torque_low
            or self.kernel.layout.torque_high is not self.torque_high
        ):
            self._buffers(rows, n_min)

    def _compiled_stack(self, robot: RobotModel, tasks: Sequence[Task]) -> CompiledTaskStack | None:
        """The compiled stack of this task list (made on its first step), or None when the
        settings or a task's kind ask for the Python path."""
        if not self.settings.compiled_tasks:
            return None
        stack = self._stack
        if stack is not None and stack.matches(tasks):
            return stack
        if not supports(tasks, robot.layout.planar):
            return None
        self._stack = CompiledTaskStack(robot, self.motion, tasks)
        return self._stack

    def __getstate__(self) -> dict[str, object]:
        state = self.__dict__.copy()
        state["_stack"] = None  # holds views on MuJoCo's arrays: made again on the next step
        state["_table"], state["_table_for"] = None, (None, None)  # addresses: likewise
        state["_steady"] = None
        # ProxQP's object pickles as an empty C++ object, which crashes the process at its
        # next update (and a deep copy is a pickle): a copy starts a new one at its next
        # ProxQP solve, not warm-started from the original's last result (so that solve
        # agrees with the original's to ProxQP's tolerance, not to the bit)
        state["_qp"] = None
        return state

    def _snapshot(self, robot: RobotModel, tasks: Sequence[Task]) -> None:
        """The stacked tasks' ``J``, reference accelerations, weights and ``Jdot nu`` into
        the row buffers: by one compiled call when the tasks allow, else task by task."""
        stack = self._compiled_stack(robot, tasks)
        self.compiled = stack is not None
        if stack is not None:
            self._ensure_buffers(stack.rows, robot.layout.n_min)
            stack.fill(robot, self._J, self._target, self._bias, self._w)
            return
        # MuJoCo's Jacobian calls read past their arrays on a bad site id (a negative one
        # would pass NumPy's indexing): the same checks as a compiled stack's
        check_indices(tasks, robot.model.nsite, robot.layout.n_min)
        blocks = [task.jacobian(robot) for task in tasks]
        rows = sum(len(block) for block in blocks)
        self._ensure_buffers(rows, blocks[0].shape[1])
        J, target, w = self._J, self._target, self._w
        start = 0
        for task, block in zip(tasks, blocks, strict=True):
            stop = start + len(block)
            J[start:stop] = block
            target[start:stop] = task.reference_acceleration(robot)
            w[start:stop] = task.weights()
            start = stop
        self._jdot_nu(robot, tasks, out=self._bias)

    def _one_call_table(self, stack: CompiledTaskStack, robot: RobotModel) -> ArrayTable:
        """The table of the one-call step, built again when the stack or the kernel (with its
        row buffers and torque-limit arrays) was made anew since."""
        stack_for, kernel_for = self._table_for
        table = self._table
        if table is None or stack_for is not stack or kernel_for is not self.kernel:
            table = step_table(
                stack,
                self.kernel,
                robot,
                self._J,
                self._target,
                self._bias,
                self._w,  # type: ignore[arg-type]
            )
            self._table, self._table_for = table, (stack, self.kernel)
        return table

    def _one_call(self, robot: RobotModel, tasks: Sequence[Task]) -> bool | None:
        """The rows and the kernel in one compiled call (``controllers.low_level.compiled_step``):
        whether the unconstrained minimiser is feasible (its solution terms then computed), or
        None when the settings or a task's kind ask for the two-call path (the control step's
        common case)."""
        if not self.settings.one_call:
            return None
        stack = self._compiled_stack(robot, tasks)
        if stack is None:
            return None
        if not robot.has_dynamics:
            raise RuntimeError("the last robot update had dynamics=False: no A, h")
        self.compiled = True
        self._ensure_buffers(stack.rows, robot.layout.n_min)
        table = self._one_call_table(stack, robot)
        stack.prepare_parameters(robot, self._w)
        feasible = rows_and_kernel(table.rows)
        stack.memoise_observers(robot, self._target)
        self._terms_ready = feasible
        # the next step may take the steady path only while each observer's memory is this
        # stack's (its marker in robot.cache points there)
        self._steady = (
            None
            if not stack.owns_its_observers()
            else (
                stack,
                table,
                self.kernel,
                self._w,
                self.torque_low,
                self.torque_high,
                self.settings,
                robot,
                *stack.steady_parts(),
            )
        )
        return feasible

    def _steady_call(self, robot: RobotModel, tasks: Sequence[Task]) -> bool | None:
        """:meth:`_one_call` when the last one found what this one would: the same settings,
        robot, torque limits, stack, row buffers and table, the stack :meth:`unchanged` for
        ``tasks``, and no observer advanced at this state yet. Then its checks are those
        identities, and ``prepare_parameters`` and ``memoise_observers`` are done inline (what
        they do in that case): 0.37 units (about 2.8 us) off KrangTray-v0's control step in the
        closed loop (against the full one-call step). None when anything differs: :meth:`_one_call`
        then."""
        steady = self._steady
        if steady is None:
            return None
        stack, table, kernel, w, low, high, settings, owner, keys, advance, weights, advanced = (
            steady
        )
        if (
            self._stack is not stack
            or self.kernel is not kernel
            or self._w is not w
            or self.torque_low is not low
            or self.torque_high is not high
            or self.settings is not settings
            or robot is not owner
            or not robot.has_dynamics
            or not stack.unchanged(tasks)  # type: ignore[union-attr]
        ):
            return None
        cache = robot.cache
        if not keys.isdisjoint(cache):
            return None  # an observer advanced at this state already: the full step
        advance.fill(1)
        w[:] = weights
        feasible: bool = rows_and_kernel(table.rows)
        cache.update(advanced)
        self.compiled = True
        self._terms_ready = feasible
        return feasible

    def _run_kernel(
        self, robot: RobotModel, iso: IsolatedDynamics | None, tasks: Sequence[Task]
    ) -> bool:
        """This state's rows, ``H``, ``g``, constraint rows and unconstrained minimiser into
        the kernel's buffers, by whichever path applies; whether the minimiser is feasible
        (what ``assemble`` and ``solve`` share; ``wip-bench profile`` times it as
        ``qp_assembly``)."""
        if iso is None:
            feasible = self._steady_call(robot, tasks)
            if feasible is None:
                feasible = self._one_call(robot, tasks)
            if feasible is not None:
                return feasible
        self._terms_ready = False
        self._snapshot(robot, tasks)
        A, h = (robot.A, robot.h) if iso is None else (None, None)
        return self.kernel.run(
            A, h, self._J, self._target, self._bias, self._w, robot.q, robot.nu, iso
        )

    def task_rows(
        self, robot: RobotModel, iso: IsolatedDynamics | None, tasks: Sequence[Task]
    ) -> tuple[Array, Array]:
        """``T`` and ``b`` of the stacked weighted tasks (the kernel's buffers: overwritten by
        the next call, copy to keep). ``iso`` None: eq. iso3 from ``robot`` in the kernel."""
        self._run_kernel(robot, iso, tasks)
        return self.kernel.T, self.kernel.b

    def _jdot_nu(self, robot: RobotModel, tasks: Sequence[Task], out: Array | None = None) -> Array:
        """``Jdot nu`` = d/dt of ``J(q) nu`` at fixed ``nu``, exact from each task's
        ``jdot_nu`` (``controllers.low_level.motion_probe``). Written into ``out`` when given."""
        self.motion.update(robot)
        parts = []
        for task in tasks:
            exact = getattr(task, "jdot_nu", None)
            if exact is None:
                raise ValueError(
                    f"task {getattr(task, 'name', task)!r} has no jdot_nu(probe): "
                    "every task of the QP needs its exact Jdot nu"
                )
            parts.append(exact(self.motion))
        return np.concatenate(parts, out=out)

    def assemble(
        self, robot: RobotModel, iso: IsolatedDynamics | None, tasks: Sequence[Task]
    ) -> tuple[Array, Array, Array, Array, Array]:
        """The QP ``min 0.5 qdd' H qdd + g' qdd  s.t.  lower <= C qdd <= upper`` of this state,
        as ``(H, g, C, lower, upper)`` (what ``solve`` hands ProxQP; the benchmark's peers
        solve the same arrays), by one call of the kernel (``controllers.low_level.kernel``),
        which also tries the unconstrained minimiser. They are the kernel's buffers,
        overwritten by the next call: copy to keep. ``iso`` None: eq. iso3 in the kernel."""
        self._feasible = self._run_kernel(robot, iso, tasks)
        k = self.kernel
        return k.H, k.g, k.C, k.lower, k.upper

    def solve(
        self, robot: RobotModel, iso: IsolatedDynamics | None, tasks: Sequence[Task]
    ) -> QPSolution:
        """The task QP of this state (``iso`` None: eq. iso3 computed in the kernel from
        ``robot``). ``proxqp_calls`` counts the steps ProxQP solved."""
        if iso is None and self._proxqp_ready and self.settings.unconstrained_first:
            # the common case first: one compiled call, its minimiser feasible
            self._feasible = feasible = self._run_kernel(robot, None, tasks)
            if feasible:
                k = self.kernel
                if self._terms_ready:  # the one-call step computed what x implies
                    self._last_actuators = actuators = k.actuators.copy()
                    return QPSolution(
                        k.x.copy(), k.nu_dot.copy(), k.generalized.copy(), actuators, True, 0
                    )
                return self._solution(k.x.copy(), iterations=0)
            k = self.kernel
            H, g, C, lower, upper = k.H, k.g, k.C, k.lower, k.upper
        else:
            H, g, C, lower, upper = self.assemble(robot, iso, tasks)
            if self._proxqp_ready and self.settings.unconstrained_first and self._feasible:
                return self._solution(self.kernel.x.copy(), iterations=0)
        self.proxqp_calls += 1
        if self._qp is None:
            self._qp = start_proxqp(H, g, C, lower, upper, self.settings)
        else:
            self._qp.update(H=H, g=g, C=C, l=lower, u=upper)
            self._qp.solve()
        results = self._qp.results
        iterations = int(results.info.iter)
        if results.info.status == _SOLVED and bool(np.all(np.isfinite(results.x))):
            self._proxqp_ready = True
            return self._solution(np.array(results.x), iterations)
        self.failures += 1
        # start the next step cold: a warm start from a failed result does not recover
        self._qp, self._proxqp_ready = None, False
        if self._last_actuators is None:
            raise RuntimeError("the first task QP was not solved: no feasible torques yet")
        nan = np.full(self.n, np.nan)
        return QPSolution(
            qdd=nan,
            nu_dot=np.full(self.n + 1, np.nan),
            generalized=nan.copy(),
            actuators=self._last_actuators,
            solved=False,
            iterations=iterations,
        )

    def _solution(self, qdd: Array, iterations: int) -> QPSolution:
        """The solved QP's answer for ``qdd``, with its ``(generalized, actuators, nu_dot)``
        (``kernel.solution_terms``; the common case of ``solve`` takes them from the one
        compiled call instead)."""
        k = self.kernel
        generalized, actuators, nu_dot = solution_terms(k.calA, k.Ph, self.M_act, k.E, k.e, qdd)
        self._last_actuators = actuators
        return QPSolution(
            qdd=qdd,
            nu_dot=nu_dot,
            generalized=generalized,
            actuators=actuators,
            solved=True,
            iterations=iterations,
        )
