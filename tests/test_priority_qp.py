"""The task QP with balance rows and priorities (controllers/low_level/priority_qp.py): the
weighted QP's answer against ProxQP on the hard-constrained problem, the strict stack's levels
against a cascade of ProxQP solves, and the weighted path without extra rows against the task
QP itself."""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np
import proxsuite
import pytest

import wip_gym  # noqa: F401
from controllers.hierarchical import HierarchicalConfig, HierarchicalController
from controllers.low_level.object_balance import CarriedObject, ObjectBalance
from controllers.low_level.priority_qp import ExtraRows, PriorityQP, row_levels, task_level
from controllers.low_level.tasks import FramePositionTask
from controllers.registry import make_policy
from tests.test_priorities import _proxqp

TOL = 1e-6


def _policy(env_id: str = "wip_gym/PlanarTray-v0", steps: int = 150, **config):
    """A unified controller after ``steps`` closed-loop steps (a state off the reset's rest)."""
    env = gym.make(env_id, reset_noise_scale=0.02)
    observation, info = env.reset(seed=3)
    policy = make_policy("unified", env, dataclasses.replace(HierarchicalConfig(), **config))
    policy.reset(observation, info)
    for _ in range(steps):
        observation, *_, info = env.step(policy(observation))
    policy.robot.update(observation["qpos"], observation["qvel"])
    policy._set_references(policy.robot)  # noqa: SLF001 - this state's task references
    return env, policy


def _balance(policy: HierarchicalController, friction: float) -> ObjectBalance:
    site = policy.robot.model.site("tray_top").id
    return ObjectBalance(policy.robot, site, CarriedObject(margin=0.0), friction)


def test_the_weighted_path_without_extra_rows_is_the_task_qp():
    _, policy = _policy()
    robot, qp = policy.robot, policy.qp
    step = PriorityQP(qp).solve(robot, policy.tasks, policy.constraints, "weighted")
    direct = qp.solve(robot, None, policy.tasks, policy.constraints)
    np.testing.assert_array_equal(step.solution.actuators, direct.actuators)
    assert not step.active and not step.relaxed


@pytest.mark.parametrize("friction", [0.3, 0.02, 1e-4])
def test_weighted_balance_rows_hold_when_they_can_and_give_least_when_not(friction):
    """At a state of the closed loop, with the cup's rows of a friction from loose to
    very thin (the tray can still tilt under it): the weighted answer meets every balance row
    when ProxQP finds the hard problem feasible (and then equals its optimum), and is relaxed
    only when it is not."""
    _, policy = _policy()
    robot, qp = policy.robot, policy.qp
    balance = _balance(policy, friction)
    H, g, C, lower, upper = (a.copy() for a in qp.assemble(robot, None, policy.tasks))
    E, e = qp.kernel.E.copy(), qp.kernel.e.copy()
    qp.motion.update(robot)
    G, b = balance.rows(robot, qp.motion)
    Gq, rhs = G @ E, -(G @ e + b)
    solver = PriorityQP(qp, slack_weight=1e8)
    qp.note_solved()
    step = solver.solve(robot, policy.tasks, (), "weighted", ExtraRows(None, (G, b)))
    x = step.solution.qdd
    unconstrained = np.linalg.solve(H, -g)
    assert step.active == bool(np.any(Gq @ unconstrained > rhs + 1e-9))
    np.testing.assert_allclose(step.solution.nu_dot, E @ x + e, atol=1e-12)
    hard = _hard_feasible(H, g, C, lower, upper, Gq, rhs)
    if hard is not None:
        assert not step.relaxed
        assert np.all(Gq @ x <= rhs + TOL)
        np.testing.assert_allclose(x, hard, atol=1e-4 * max(1.0, np.abs(hard).max()))
    else:
        assert step.relaxed


def _hard_feasible(H, g, C, lower, upper, Gq, rhs) -> np.ndarray | None:
    """The QP with the balance rows hard, or None where ProxQP finds it infeasible."""
    qp = proxsuite.proxqp.dense.QP(len(g), 0, len(C) + len(rhs))
    qp.settings.eps_abs = 1e-11
    qp.settings.eps_rel = 0.0
    qp.settings.max_iter = 50000
    qp.init(
        H,
        g,
        None,
        None,
        np.vstack([C, Gq]),
        np.concatenate([lower, np.full(len(rhs), -1e20)]),
        np.concatenate([upper, rhs]),
        False,
    )
    qp.solve()
    if qp.results.info.status != proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED:
        return None
    return np.array(qp.results.x)


def _strict_problem() -> tuple[Any, ...]:
    """The unified-upright policy at reset and its strict problem's arrays: the limits
    ``C, lower, upper``, the task rows ``T, b_t``, the kernel ``E, e``, the cup's balance rows
    ``G, b`` (friction 0.05) and over ``qdd``, ``Gq, rhs``."""
    _, policy = _policy()
    robot, qp = policy.robot, policy.qp
    balance = _balance(policy, 0.05)
    _, _, C, lower, upper = (a.copy() for a in qp.assemble(robot, None, policy.tasks))
    T, b_t = qp.kernel.T.copy(), qp.kernel.b.copy()
    E, e = qp.kernel.E.copy(), qp.kernel.e.copy()
    qp.motion.update(robot)
    G, b = balance.rows(robot, qp.motion)
    return policy, robot, qp, C, lower, upper, T, b_t, E, e, G, b, G @ E, -(G @ e + b)


def test_the_strict_stack_keeps_each_level_optimal_under_those_above():
    """Strict with the cup's rows: the balance level is as good as the balance task alone can
    be under the hard limits, the object's rows then hold as well as they can without worsening
    it, and the motion level is the best under both (a cascade of ProxQP solves)."""
    policy, robot, qp, C, lower, upper, T, b_t, E, e, G, b, Gq, rhs = _strict_problem()
    step = PriorityQP(qp).solve(robot, policy.tasks, (), "strict", ExtraRows(None, (G, b)))
    assert step.solution.solved
    x = step.solution.qdd
    levels = [task_level(task) for task in policy.tasks]
    assert levels[0] == "balance" and "motion" in levels and levels[-1] == "posture"
    rows = np.repeat(levels, [len(np.atleast_1d(t.weights())) for t in _inner(policy.tasks)])
    n = len(x)
    # level 1: the balance task's best under the hard rows
    Tb, bb = T[rows == "balance"], b_t[rows == "balance"]
    best = _proxqp(Tb.T @ Tb + 1e-12 * np.eye(n), -Tb.T @ bb, np.zeros((0, n)), np.zeros(0),
                   C, lower, upper)  # fmt: skip
    r_best = np.linalg.norm(Tb @ best - bb)
    assert np.linalg.norm(Tb @ x - bb) <= r_best + 1e-6
    # level 2: the object rows at least as well met as any point keeping level 1
    violation = np.maximum(Gq @ x - rhs, 0.0).max()
    assert violation <= 1e-6 or step.relaxed
    # level 3: the motion rows no worse than the best point that keeps levels 1 and 2
    Tm, bm = T[rows == "motion"], b_t[rows == "motion"]
    keep = _proxqp(Tm.T @ Tm + 1e-12 * np.eye(n), -Tm.T @ bm, Tb, Tb @ x,
                   np.vstack([C, Gq]), np.concatenate([lower, np.full(len(rhs), -1e20)]),
                   np.concatenate([upper, np.maximum(rhs, Gq @ x) + 1e-9]))  # fmt: skip
    assert np.linalg.norm(Tm @ x - bm) <= np.linalg.norm(Tm @ keep - bm) + 1e-5


def _hand(policy: HierarchicalController) -> FramePositionTask:
    from controllers.low_level.task_stack import unwrap

    return next(
        inner for inner, _ in map(unwrap, policy.tasks) if isinstance(inner, FramePositionTask)
    )


def test_row_levels_move_the_named_rows_to_the_posture_level():
    _, policy = _policy(steps=0)
    hand = _hand(policy)
    plain = row_levels(policy.tasks)
    sizes = [len(np.atleast_1d(t.weights())) for t in _inner(policy.tasks)]
    assert plain == list(np.repeat([task_level(t) for t in policy.tasks], sizes))
    moved = row_levels(policy.tasks, [(hand, (0, 2))])
    start = sum(sizes[: _inner(policy.tasks).index(hand)])
    changed = [i for i, (a, b) in enumerate(zip(plain, moved, strict=True)) if a != b]
    assert changed == [start, start + 2]
    assert moved[start] == moved[start + 2] == "posture" and moved[start + 1] == "motion"
    with pytest.raises(ValueError, match="not a task here"):
        row_levels(policy.tasks, [(FramePositionTask(hand.site, hand.target), (0,))])
    with pytest.raises(ValueError, match="row 3"):
        row_levels(policy.tasks, [(hand, (3,))])


def test_rows_moved_to_the_posture_level_trade_with_the_posture_under_the_levels_above():
    """Strict with the cup's rows and the hand's forward row in the posture level: the balance,
    object and motion levels (without that row) each optimal under those above, and the posture
    level (posture, the moved row and ``eps ||qdd||^2``) the best that keeps them (a cascade of
    ProxQP solves)."""
    policy, robot, qp, C, lower, upper, T, b_t, E, e, G, b, Gq, rhs = _strict_problem()
    moved = [(_hand(policy), (0,))]
    step = PriorityQP(qp).solve(
        robot, policy.tasks, (), "strict", ExtraRows(None, (G, b)), posture_rows=moved
    )
    assert step.solution.solved
    x, n = step.solution.qdd, len(step.solution.qdd)
    rows = np.array(row_levels(policy.tasks, moved))
    assert (rows == "posture").sum() == (np.array(row_levels(policy.tasks)) == "posture").sum() + 1
    Tb, bb = T[rows == "balance"], b_t[rows == "balance"]
    best = _proxqp(Tb.T @ Tb + 1e-12 * np.eye(n), -Tb.T @ bb, np.zeros((0, n)), np.zeros(0),
                   C, lower, upper)  # fmt: skip
    assert np.linalg.norm(Tb @ x - bb) <= np.linalg.norm(Tb @ best - bb) + 1e-6
    assert np.maximum(Gq @ x - rhs, 0.0).max() <= 1e-6 or step.relaxed
    inequalities = np.vstack([C, Gq])
    low = np.concatenate([lower, np.full(len(rhs), -1e20)])
    high = np.concatenate([upper, np.maximum(rhs, Gq @ x) + 1e-9])
    Tm, bm = T[rows == "motion"], b_t[rows == "motion"]
    keep = _proxqp(Tm.T @ Tm + 1e-12 * np.eye(n), -Tm.T @ bm, Tb, Tb @ x, inequalities, low, high)
    assert np.linalg.norm(Tm @ x - bm) <= np.linalg.norm(Tm @ keep - bm) + 1e-5
    # the posture level: its rows and eps ||qdd||^2, the levels above held where x holds them
    eps = qp.settings.regularization
    Tp, bp = T[rows == "posture"], b_t[rows == "posture"]
    above = np.vstack([Tb, Tm])
    keep = _proxqp(Tp.T @ Tp + eps * np.eye(n), -Tp.T @ bp, above, above @ x, inequalities,
                   low, high)  # fmt: skip

    def posture_cost(y: np.ndarray) -> float:
        return float(np.sum((Tp @ y - bp) ** 2) + eps * y @ y)

    assert posture_cost(x) <= posture_cost(keep) * (1 + 1e-6) + 1e-8


def _inner(tasks):
    from controllers.low_level.task_stack import unwrap

    return [unwrap(task)[0] for task in tasks]


def test_every_unified_controller_runs_strict():
    """``priority="strict"`` on the unified controller in closed loop (PlanarTray-v0, 1 s):
    it balances (no fall) and the DAQP stack answers every step."""
    env, policy = _policy(steps=0, priority="strict")
    observation, info = env.reset(seed=0)
    policy.reset(observation, info)
    for _ in range(1000):
        observation, _, terminated, _, info = env.step(policy(observation))
        assert not terminated
    assert not info["fallen"]
    assert policy.controller_counters()["qp_fallbacks"] == 0


def test_bad_priorities_are_refused():
    with pytest.raises(ValueError, match="priority"):
        HierarchicalConfig(priority="lexicographic")  # type: ignore[arg-type]
    _, policy = _policy(steps=0)
    with pytest.raises(ValueError, match="priority"):
        PriorityQP(policy.qp).solve(policy.robot, policy.tasks, (), "both")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="slack_weight"):
        PriorityQP(policy.qp, slack_weight=0.0)
