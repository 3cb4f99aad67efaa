"""The task QP's shortcut: the unconstrained minimiser, taken only when it satisfies
every constraint, is ProxQP's answer; a binding constraint still goes to ProxQP."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from test_wbc import _limits, _load, _realistic_tasks, _set_state

from controllers.low_level.isolated_dynamics import isolated_dynamics
from controllers.low_level.task_qp import QPSettings, TaskQP
from wip_gym.robot_model import RobotModel

DATA = Path(__file__).parent / "data"


@pytest.mark.parametrize("name", ["krang", "planar7"])
def test_shortcut_equals_proxqp_and_yields_to_it_when_a_limit_binds(name: str) -> None:
    robot = RobotModel(_load(name))
    low, high = _limits(robot)
    fast = TaskQP(robot, low, high, QPSettings())
    proxqp = TaskQP(robot, low, high, dataclasses.replace(QPSettings(), unconstrained_first=False))
    shortcuts = 0
    for seed in range(6):
        _set_state(robot, 500 + seed, still=True)
        tasks = _realistic_tasks(robot)
        iso = isolated_dynamics(robot)
        a, b = fast.solve(robot, iso, tasks), proxqp.solve(robot, iso, tasks)
        assert a.solved and b.solved and b.iterations > 0
        shortcuts += a.iterations == 0
        np.testing.assert_allclose(a.qdd, b.qdd, rtol=0, atol=1e-6 * max(1, abs(b.qdd).max()))
        np.testing.assert_allclose(a.actuators, b.actuators, rtol=0, atol=1e-6)
    assert shortcuts >= 5  # the first solve creates ProxQP's object; then the shortcut holds
    # limits at 5 %: the unconstrained answer breaks them, ProxQP is called and they hold
    fast.torque_low, fast.torque_high = _limits(robot, 0.05)
    solution = fast.solve(robot, iso, tasks)
    assert solution.solved and solution.iterations > 0
    assert np.all(solution.actuators >= fast.torque_low - 1e-6)
    assert np.all(solution.actuators <= fast.torque_high + 1e-6)


def test_recorded_closed_loop_qps_take_the_shortcut() -> None:
    """On the recorded KrangTray QPs the unconstrained minimiser is feasible and is ProxQP's
    recorded solution."""
    with np.load(DATA / "lowlevel_krang.npz") as data:
        H, g, C, lower, upper, x = (data[k] for k in ("H", "g", "C", "lower", "upper", "x"))
    for i in range(len(H)):
        qdd = np.linalg.solve(H[i], -g[i])
        assert np.all(C[i] @ qdd >= lower[i]) and np.all(C[i] @ qdd <= upper[i])
        np.testing.assert_allclose(qdd, x[i], rtol=0, atol=1e-6)
