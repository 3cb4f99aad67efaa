"""``CompiledTaskStack.matches``: a stack serves a task list only while what it was built from
is unchanged (``task_stack.structure``), whatever a step changes of the tasks' targets and
gains."""

from __future__ import annotations

import dataclasses

import numpy as np
from dynamics_reference import random_minimal_state
from test_compiled_tasks import _task_set
from test_wbc import _load

from controllers.low_level.disturbance_tasks import DisturbanceRejectingTask
from controllers.low_level.motion_probe import MotionProbe
from controllers.low_level.task_stack import CompiledTaskStack, structure
from controllers.low_level.tasks import FramePositionTask, PostureTask
from wip_gym.robot_model import RobotModel


def test_matches_follows_the_structure() -> None:
    robot = RobotModel(_load("krang"))
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(5))))
    tasks = _task_set(robot, observed=True)
    stack = CompiledTaskStack(robot, MotionProbe(robot), tasks)
    built = structure(tasks)

    def agrees(candidate: list[object]) -> bool:
        result = stack.matches(candidate)
        assert result == (structure(candidate) == built)
        return result

    assert agrees(list(tasks))
    # targets, gains and weights may change every step
    posture = next(t for t in tasks if isinstance(t, PostureTask))
    posture.target = posture.target + 0.1
    posture.kp = 3.0
    assert agrees(tasks)
    # another list, a task replaced, one left out, the order changed
    assert not agrees(tasks[:-1])
    assert not agrees([*tasks[1:], tasks[0]])
    assert not agrees([dataclasses.replace(posture) if t is posture else t for t in tasks])
    # a frame task's site, a posture task's columns (in place too), an observer's task
    wrapped = next(t for t in tasks if isinstance(t, DisturbanceRejectingTask))
    frame = wrapped.task
    assert isinstance(frame, FramePositionTask)
    site = frame.site
    frame.site = site + 1
    assert not agrees(tasks)
    frame.site = site
    assert agrees(tasks)
    posture.columns[0] += 1
    assert not agrees(tasks)
    posture.columns[0] -= 1
    assert agrees(tasks)
    wrapped.task = dataclasses.replace(frame)
    assert not agrees(tasks)
    wrapped.task = frame
    assert agrees(tasks)


def test_unchanged_holds_only_where_matches_does_and_after_it() -> None:
    """``unchanged`` (the control step's cheap check) is True only when ``matches`` is, and
    only once ``matches`` and ``prepare_parameters`` have looked at the current count of store
    events: any assignment to a task or an observer, or a posture task's columns changed in
    place, makes it False until they look again."""
    robot = RobotModel(_load("krang"))
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(6))))
    tasks = _task_set(robot, observed=True)
    stack = CompiledTaskStack(robot, MotionProbe(robot), tasks)
    w = np.zeros(stack.rows)

    def look(candidate: list[object]) -> bool:
        matched = stack.matches(candidate)
        stack.prepare_parameters(robot, w)
        return matched

    assert stack.unchanged(tasks)  # as built
    posture = next(t for t in tasks if isinstance(t, PostureTask))
    posture.name = "posture"  # an assignment
    assert not stack.unchanged(tasks)
    assert stack.matches(tasks) and not stack.unchanged(tasks)  # prepare_parameters not yet
    stack.prepare_parameters(robot, w)
    assert stack.unchanged(tasks) and stack.unchanged(list(tasks))  # another list, same tasks
    assert not stack.unchanged(tasks[:-1]) and not stack.unchanged([*tasks[1:], tasks[0]])
    wrapped = next(t for t in tasks if isinstance(t, DisturbanceRejectingTask))
    frame = wrapped.task
    assert isinstance(frame, FramePositionTask)
    changes = [
        lambda: setattr(frame, "site", frame.site),  # an assignment, even of the same site
        lambda: setattr(wrapped, "task", frame),
        lambda: setattr(posture, "name", "posture"),
    ]
    for change in changes:
        change()
        assert not stack.unchanged(tasks)
        assert look(tasks) and stack.unchanged(tasks)  # all of these leave it matching
    # a gain or a target written into the stack's arrays is no store event
    posture.kp = 4.0
    posture.target[0] += 0.1
    assert stack.unchanged(tasks)
    posture.columns[0] += 1  # in place: no assignment, seen by the columns' check
    assert not stack.unchanged(tasks) and not look(tasks)
    posture.columns[0] -= 1
    assert look(tasks) and stack.unchanged(tasks)
    frame.site = frame.site + 1
    assert not stack.unchanged(tasks) and not look(tasks)
