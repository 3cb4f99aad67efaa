"""The task QP with a carried object's balance rows and a choice of priorities.

:class:`PriorityQP` solves the same QP as :class:`controllers.low_level.task_qp.TaskQP` (which
fills it, on its compiled or readable path) with two optional additions, both over ``nu_dot``
and mapped to the QP's variables by the isolated dynamics ``nu_dot = E qdd + e`` (eq. ``iso3``):

* **cost rows** ``A nu_dot + a -> 0`` (weighted) beside the tasks (``unified-upright``'s tangential
  specific force at the cup and its drive row, docs/upright.md §3);
* **balance rows** ``G nu_dot + b <= 0``: the carried object's friction, contact and tipping
  conditions (``controllers.low_level.object_balance``).

Two priorities (``HierarchicalConfig.priority``; docs/upright.md §4):

* ``weighted`` (the paper's): one QP. The unconstrained minimiser is tried first and taken when
  it meets every row (the balance rows then are *inactive*); otherwise DAQP solves it with the
  balance rows softened by one slack per row, ``s >= G q + b``, ``s >= 0``, under an exact
  penalty ``w (s + s^2 / 2)``: they hold whenever the torque and joint limits let them (at
  multipliers below ``w``), and are *relaxed* (least) where they do not. A hard row that
  cannot hold would leave no torques.
* ``strict``: levels solved lexicographically by DAQP (``controllers.low_level.priorities``):
  the torque and joint limits hard, then ``balance`` (the ``theta`` task), ``object`` (the
  balance rows), ``motion`` (the hands, the heading and the cost rows), ``posture`` (posture,
  speed regularisation, a user's tasks, and the QP's ``eps ||qdd||^2``). A level is met as well
  as it can be without worsening any level above it; the object's rows relaxed under the balance
  are counted. The caller may put chosen rows of the motion tasks in the posture level
  (``posture_rows``), where they trade with the body's shape by their weights as in the weighted
  QP: ``unified-upright``'s drive row and its hands' forward rows (docs/upright.md §4).

Without cost and balance rows and with ``weighted``, :meth:`PriorityQP.solve` is
``TaskQP.solve`` itself. The rows may come as arrays (:class:`ExtraRows`) or as task and
constraint objects of the QP (``controllers.low_level.object_tasks``: the cost rows as tasks,
the balance rows as its last constraint rows, ``balance_rows``), which the one-call step
computes with the rest (docs/upright.md §4): the weighted QP's unconstrained minimiser that
meets every row is then the compiled call's, and the other paths split the balance rows off.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import daqp
import numpy as np
from numpy.typing import NDArray

from controllers.low_level.priorities import INFINITY, SOLVED_FLAGS, Level, solve_lexicographic
from controllers.low_level.task_qp import QPSolution, TaskQP
from controllers.low_level.task_stack import rows_of, unwrap
from controllers.low_level.tasks import PostureTask, ThetaTask
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]
Priority = Literal["weighted", "strict"]
PRIORITIES: tuple[str, ...] = ("weighted", "strict")
#: a balance row counts as relaxed when its slack exceeds this (units of the object's weight)
RELAXED_TOLERANCE = 1e-6


@dataclass(frozen=True)
class ExtraRows:
    """Rows over ``nu_dot`` beside the tasks: ``cost`` ``(A, a)``, already weighted
    (minimised: ``||A nu_dot + a||^2``; None: none) and the balance ``(G, b)`` with
    ``G nu_dot + b <= 0`` (None: no object)."""

    cost: tuple[Array, Array] | None = None
    balance: tuple[Array, Array] | None = None


@dataclass(frozen=True)
class PriorityStep:
    """One step's answer: the QP's solution, whether the balance rows constrained it (the
    minimiser broke one) and whether any was relaxed."""

    solution: QPSolution
    active: bool
    relaxed: bool


#: ``(task, row indices)``: rows of a task that the strict stack puts in its posture level
PostureRows = Sequence[tuple[Any, Sequence[int]]]


def task_level(task: Any) -> str:
    """The strict stack's level of a task: ``balance`` for ``theta``, ``posture`` for posture
    and speed regularisation, ``motion`` for the others (hands, heading, a user's tasks)."""
    inner, _ = unwrap(task)
    if isinstance(inner, ThetaTask):
        return "balance"
    if isinstance(inner, PostureTask):
        return "posture"
    return "motion"


def row_levels(tasks: Sequence[Any], posture_rows: PostureRows = ()) -> list[str]:
    """The strict stack's level of every row of ``tasks``, in order: each task's
    (``task_level``), but ``posture`` for the rows ``posture_rows`` names (``PriorityQP.solve``).
    ``ValueError`` for a task not in ``tasks`` or a row index outside its task's rows."""
    inner = [unwrap(task)[0] for task in tasks]
    levels = [[task_level(task)] * rows_of(own) for task, own in zip(tasks, inner, strict=True)]
    for task, indices in posture_rows:
        found = [i for i, own in enumerate(inner) if task is tasks[i] or task is own]
        if not found:
            raise ValueError(f"posture_rows: {getattr(task, 'name', task)!r} is not a task here")
        rows = levels[found[0]]
        for index in indices:
            if not 0 <= index < len(rows):
                raise ValueError(
                    f"posture_rows: row {index} of {getattr(task, 'name', task)!r}, which has "
                    f"{len(rows)}"
                )
            rows[index] = "posture"
    return [level for task_rows in levels for level in task_rows]


class PriorityQP:
    """Solve a :class:`TaskQP`'s problem with extra rows, weighted or strict (module
    docstring). ``slack_weight``: the weight of a balance row's slack in the weighted QP."""

    def __init__(self, qp: TaskQP, slack_weight: float = 1e6) -> None:
        if not (np.isfinite(slack_weight) and slack_weight > 0):
            raise ValueError(f"slack_weight must be positive, got {slack_weight!r}")
        self.qp = qp
        self.slack_weight = slack_weight
        self._levels: list[str] | None = None
        self._levels_of: tuple[int, ...] = ()

    def solve(
        self,
        robot: RobotModel,
        tasks: Sequence[Any],
        constraints: Sequence[Any],
        priority: Priority,
        extra: ExtraRows = ExtraRows(),
        balance_rows: int = 0,
        posture_rows: PostureRows = (),
    ) -> PriorityStep:
        """The step's solution (``robot`` updated to the state; eq. iso3 from it).

        ``balance_rows``: how many of the constraints' last rows are the object's balance rows,
        ``G nu_dot + b <= 0`` (an ``object_tasks.ObjectBalanceConstraint`` last in
        ``constraints``): the one-call step computes them with the rest, and they are soft
        (weighted) or the object's level (strict) as ``extra.balance``'s, which must then be
        None. Their unconstrained minimiser, when it meets every row, is the compiled call's.

        ``posture_rows``: ``(task, row indices)`` pairs, each task one of ``tasks`` (as given or
        unwrapped): with ``strict``, those rows are in the posture level instead of their task's
        (``task_level``); the weighted QP, one level, has no use for them. ``ValueError`` for a
        task not in ``tasks`` or an index outside its rows."""
        if priority not in PRIORITIES:
            raise ValueError(f"priority must be one of {PRIORITIES}, got {priority!r}")
        if balance_rows and extra.balance is not None:
            raise ValueError("balance rows given twice: in the constraints and in extra")
        qp = self.qp
        weighted = priority == "weighted" and extra.cost is None and extra.balance is None
        if weighted and not balance_rows:
            return PriorityStep(qp.solve(robot, None, tasks, constraints), False, False)
        H, g, C, lower, upper = qp.assemble(robot, None, tasks, constraints)
        if weighted and (shortcut := qp.shortcut()) is not None:  # the balance rows met too
            return PriorityStep(shortcut, False, False)
        k = qp.kernel
        assert k is not None
        E, e = k.E, k.e
        if extra.cost is not None:
            A, a = extra.cost
            cost_T, cost_b = A @ E, -(A @ e + a)
        else:
            cost_T, cost_b = np.zeros((0, len(g))), np.zeros(0)
        if extra.balance is not None:
            G, b = extra.balance
            Gq, rhs = G @ E, -(G @ e + b)
        elif balance_rows:
            hard = len(C) - balance_rows
            Gq, rhs = C[hard:], upper[hard:]
            C, lower, upper = C[:hard], lower[:hard], upper[:hard]
        else:
            Gq, rhs = np.zeros((0, len(g))), np.zeros(0)
        if priority == "strict":
            levels = row_levels(tasks, posture_rows)
            return self._strict(levels, k.T, k.b, cost_T, cost_b, C, lower, upper, Gq, rhs)
        H = H + cost_T.T @ cost_T
        g = g - cost_T.T @ cost_b
        x = np.linalg.solve(H, -g)
        Cx = C @ x
        meets = bool(np.all((Cx >= lower - 1e-9) & (Cx <= upper + 1e-9)))
        balanced = bool(np.all(Gq @ x <= rhs + 1e-9))
        if meets and balanced and qp.ready_for_shortcut:
            return PriorityStep(qp.solution_for(x, 0), False, False)
        return self._weighted(H, g, C, lower, upper, Gq, rhs, active=not balanced)

    # ----------------------------------------------------------------- weighted
    def _weighted(
        self,
        H: Array,
        g: Array,
        C: Array,
        lower: Array,
        upper: Array,
        Gq: Array,
        rhs: Array,
        active: bool,
    ) -> PriorityStep:
        """DAQP on ``(qdd, s)``: the balance rows softened by their slack ``s >= 0``, which
        costs ``w (s + s^2 / 2)`` (``w`` the slack weight). The linear part makes the penalty
        exact: where the rows can hold and their multipliers are below ``w``, the answer is the
        hard-constrained QP's, with ``s = 0`` (a quadratic penalty alone would leave every
        active row relaxed by its multiplier over ``w``). DAQP, a dual active-set solver, ends
        on the active set exactly; ProxQP, unpreconditioned as the task QP runs it, did not
        converge on these rows at ``w = 1e6`` (tests/test_priority_qp.py)."""
        n, r = len(g), len(rhs)
        w = self.slack_weight
        Ha = np.zeros((n + r, n + r))
        Ha[:n, :n] = H
        Ha[n:, n:] = w * np.eye(r)
        ga = np.concatenate([g, np.full(r, w)])
        Ca = np.zeros((len(C) + 2 * r, n + r))
        Ca[: len(C), :n] = C
        Ca[len(C) : len(C) + r, :n] = Gq
        Ca[len(C) : len(C) + r, n:] = -np.eye(r)
        Ca[len(C) + r :, n:] = np.eye(r)
        la = np.concatenate([np.maximum(lower, -INFINITY), np.full(r, -INFINITY), np.zeros(r)])
        ua = np.concatenate([np.minimum(upper, INFINITY), rhs, np.full(r, INFINITY)])
        z, _, flag, info = daqp.solve(Ha, ga, Ca, ua, la, np.zeros(len(Ca), dtype=np.intc))
        z = np.asarray(z, dtype=float)
        qp = self.qp
        iterations = int(info.get("iterations", 0))
        if flag not in SOLVED_FLAGS or not np.all(np.isfinite(z)):
            return PriorityStep(qp.fallback(iterations), active, False)
        qp.note_solved()
        relaxed = bool(r and z[n:].max() > RELAXED_TOLERANCE)
        return PriorityStep(qp.solution_for(z[:n], iterations), active or relaxed, relaxed)

    # ------------------------------------------------------------------- strict
    def _strict(
        self,
        levels_of_rows: Sequence[str],
        T: Array,
        b: Array,
        cost_T: Array,
        cost_b: Array,
        C: Array,
        lower: Array,
        upper: Array,
        Gq: Array,
        rhs: Array,
    ) -> PriorityStep:
        """DAQP's levels (module docstring) on the task rows split by ``levels_of_rows`` (one
        level name per row of ``T``)."""
        n = T.shape[1]
        rows = {"balance": [], "motion": [], "posture": []}  # type: dict[str, list[int]]
        for index, level in enumerate(levels_of_rows):
            rows[level].append(index)
        eps = np.sqrt(self.qp.settings.regularization)

        def block(name: str, A: Array, a: Array) -> tuple[Array, Array]:
            index = rows[name]
            return np.vstack([T[index], A]), np.concatenate([b[index], a])

        levels = [Level.equalities("balance", *block("balance", T[:0], b[:0]))]
        if len(rhs):
            levels.append(Level.inequalities("object", Gq, rhs))
        levels.append(Level.equalities("motion", *block("motion", cost_T, cost_b)))
        levels.append(Level.equalities("posture", *block("posture", eps * np.eye(n), np.zeros(n))))
        answer = solve_lexicographic(C, lower, upper, levels)
        qp = self.qp
        if not answer.solved:
            return PriorityStep(qp.fallback(0), bool(len(rhs)), False)
        qp.note_solved()
        active = bool(len(rhs) and np.any(Gq @ answer.x >= rhs - 1e-9))
        relaxed = answer.slack.get("object", 0.0) > RELAXED_TOLERANCE
        return PriorityStep(qp.solution_for(answer.x, 0), active or relaxed, relaxed)
