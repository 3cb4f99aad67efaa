"""``StoredParameters``: a compiled task stack keeps the tasks' gains, targets and weights in
its own arrays (``controllers.low_level.tasks``), and every way a user changes them on the task
objects reaches the compiled rows as it reaches the Python path."""

from __future__ import annotations

import copy
import dataclasses
import pickle

import numpy as np
import pytest
from dynamics_reference import random_minimal_state
from test_compiled_tasks import _close, _python_rows, _random_rotation, _task_set
from test_wbc import _load

from controllers.low_level.motion_probe import MotionProbe
from controllers.low_level.task_stack import CompiledTaskStack, supports
from controllers.low_level.tasks import (
    FrameOrientationTask,
    FramePositionTask,
    PostureTask,
    SpinTask,
    Task,
    ThetaTask,
)
from wip_gym.robot_model import RobotModel


def _of(tasks: list[Task], kind: type) -> list:
    """The tasks of ``kind``, unwrapped from their observers."""
    inner = [getattr(task, "task", task) for task in tasks]
    return [task for task in inner if type(task) is kind]


def _buffers(stack: CompiledTaskStack, n: int) -> tuple[np.ndarray, ...]:
    rows = stack.rows
    return np.zeros((rows, n)), np.zeros(rows), np.zeros(rows), np.zeros(rows)


def _change(tasks: list[Task], step: int) -> None:
    """Every way of changing a parameter: scalars assigned, targets assigned and changed in
    place, weights assigned (a scalar spread over rows, an array in place)."""
    theta = _of(tasks, ThetaTask)[0]
    theta.theta_d += 0.01
    theta.kp = 40.0 + step
    theta.weight = 5.0 + step
    theta.set_desired(theta.theta_d, 0.03 * step, -0.2 * step)
    for spin in _of(tasks, SpinTask):
        spin.psi_d = 0.02 * step
        spin.psidd_d = -0.1
        spin.kv = 15.0
        spin.set_desired(spin.psi_d, 0.1 + step, spin.psidd_d)
    positions = _of(tasks, FramePositionTask)
    positions[0].target[0] += 0.01  # in place
    positions[-1].target = positions[-1].target + np.array([0.0, 0.005, -0.01])
    positions[0].weight = 2.0 + step
    weights = np.asarray(positions[-1].weight)
    if weights.ndim:  # a per-row weight: changed in place
        weights[1] += 0.5
    orientations = _of(tasks, FrameOrientationTask)
    orientations[0].target = orientations[0].target @ _random_rotation(
        np.random.default_rng(step), 0.05
    )
    orientations[-1].target[:] = orientations[-1].target.T  # in place, another rotation
    orientations[-1].kp = 120.0
    posture = _of(tasks, PostureTask)[0]
    posture.target[1] -= 0.02
    posture.joint_weights[2] = 3.0 + step
    posture.kv = 25.0


@pytest.mark.parametrize("name", ["krang", "planar7"])
def test_every_change_to_a_task_reaches_the_compiled_rows(name: str) -> None:
    robot = RobotModel(_load(name))
    reference_robot = RobotModel(robot.model)
    q, nu = random_minimal_state(robot, np.random.default_rng(4))
    for model in (robot, reference_robot):
        model.update(*robot.full_state(q, nu))
    compiled_tasks, python_tasks = _task_set(robot, True), _task_set(reference_robot, True)
    stack = CompiledTaskStack(robot, MotionProbe(robot), compiled_tasks)
    probe = MotionProbe(reference_robot)
    buffers = _buffers(stack, robot.layout.n_min)
    for step in range(4):
        for tasks in (compiled_tasks, python_tasks):
            _change(tasks, step)
        robot.update(*robot.full_state(q + 1e-3 * step * nu, nu))
        reference_robot.update(*robot.full_state(q + 1e-3 * step * nu, nu))
        stack.fill(robot, *buffers)
        expected = _python_rows(reference_robot, probe, python_tasks)
        for ours, theirs in zip(buffers, expected, strict=True):
            _close(ours, theirs)
    # the stack's arrays are the parameters' one source: the tasks' arrays are views on them
    posture = _of(compiled_tasks, PostureTask)[0]
    assert np.shares_memory(posture.target, stack.row_target)
    assert np.shares_memory(posture.joint_weights, stack.weights)
    assert all(
        np.shares_memory(t.target, stack.targets) for t in _of(compiled_tasks, FramePositionTask)
    )


def test_a_copied_task_holds_its_own_values() -> None:
    """A copy (shallow or deep), a pickle or a ``dataclasses.replace`` of a stored task writes
    into no stack."""
    robot = RobotModel(_load("krang"))
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(2))))
    tasks = _task_set(robot, False)
    stack = CompiledTaskStack(robot, MotionProbe(robot), tasks)
    params, targets, weights = stack.params.copy(), stack.targets.copy(), stack.weights.copy()
    row_target = stack.row_target.copy()
    twins = (
        [copy.copy(task) for task in tasks],
        copy.deepcopy(tasks),
        pickle.loads(pickle.dumps(tasks)),
        [dataclasses.replace(task) for task in tasks],
    )
    for twin in twins:
        assert all(task.stored_by() is None for task in twin)
        _change(twin, 3)
        np.testing.assert_array_equal(stack.params, params)
        np.testing.assert_array_equal(stack.targets, targets)
        np.testing.assert_array_equal(stack.weights, weights)
        np.testing.assert_array_equal(stack.row_target, row_target)
    # the original still writes into its stack
    _of(tasks, ThetaTask)[0].theta_d = 0.123
    assert stack.params[0, 2] == 0.123


def test_set_desired_is_three_assignments() -> None:
    """``set_desired`` on a theta and a spin task, stored or not, leaves the task and its
    stack's row as assigning the three attributes does."""
    robot = RobotModel(_load("krang"))
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(5))))
    for stored in (False, True):
        tasks, twins = _task_set(robot, False), _task_set(robot, False)
        stacks = (
            [CompiledTaskStack(robot, MotionProbe(robot), group) for group in (tasks, twins)]
            if stored
            else []
        )
        for kind in (ThetaTask, SpinTask):
            task, twin = _of(tasks, kind)[0], _of(twins, kind)[0]
            task.set_desired(0.1, -0.2, 0.3)
            for name, value in zip(kind.desired_names, (0.1, -0.2, 0.3), strict=True):
                setattr(twin, name, value)
            assert dataclasses.asdict(task) == dataclasses.asdict(twin)
            assert [getattr(task, name) for name in kind.desired_names] == [0.1, -0.2, 0.3]
        if stored:
            np.testing.assert_array_equal(stacks[0].params, stacks[1].params)
            row = stacks[0].params[[type(t) is ThetaTask for t in tasks].index(True)]
            np.testing.assert_array_equal(row[2:5], (0.1, -0.2, 0.3))
            # a value the stack's array refuses changes neither the attribute nor the array,
            # as a refused assignment does (the entries before it are set)
            theta = _of(tasks, ThetaTask)[0]
            with pytest.raises((TypeError, ValueError)):
                theta.set_desired(0.4, np.zeros(2), 0.6)  # type: ignore[arg-type]
            assert (theta.theta_d, theta.thetad_d, theta.thdd_d) == (0.4, -0.2, 0.3)
            np.testing.assert_array_equal(row[2:5], (0.4, -0.2, 0.3))


def test_two_stacks_sharing_tasks_both_read_them_right() -> None:
    """A task stored by a second stack is taken back by the first before its next call."""
    robot = RobotModel(_load("krang"))
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(6))))
    tasks = _task_set(robot, False)
    first = CompiledTaskStack(robot, MotionProbe(robot), tasks)
    second = CompiledTaskStack(robot, MotionProbe(robot), tasks)  # stores them now
    theta = _of(tasks, ThetaTask)[0]
    position = _of(tasks, FramePositionTask)[0]
    for stack in (first, second, first):
        theta.theta_d += 0.05
        position.target = position.target + 0.01
        buffers = _buffers(stack, robot.layout.n_min)
        stack.fill(robot, *buffers)
        assert stack.params[0, 2] == theta.theta_d
        np.testing.assert_array_equal(stack.targets[2, :3], position.target)
        assert np.shares_memory(position.target, stack.targets)


def test_a_target_of_another_shape_is_refused_at_the_next_call() -> None:
    robot = RobotModel(_load("krang"))
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(7))))
    tasks = _task_set(robot, False)
    stack = CompiledTaskStack(robot, MotionProbe(robot), tasks)
    buffers = _buffers(stack, robot.layout.n_min)
    position = _of(tasks, FramePositionTask)[0]
    position.target = np.zeros(4)  # the task leaves the stack's arrays ...
    assert position.stored_by() is None
    with pytest.raises(ValueError, match=r"task 'ee_position': its target of shape \(4,\)"):
        stack.fill(robot, *buffers)  # ... and the stack cannot hold it
    position.target = np.zeros(3)
    stack.fill(robot, *buffers)
    np.testing.assert_array_equal(stack.targets[2, :3], 0.0)


def test_a_task_listed_twice_runs_the_python_path() -> None:
    """One task object twice in a list: its parameters could live in one place of the arrays
    only, so the compiled rows are not used for it."""
    robot = RobotModel(_load("krang"))
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(1))))
    tasks = _task_set(robot, False)
    assert supports(tasks, robot.layout.planar)
    assert not supports([*tasks, tasks[2]], robot.layout.planar)
