"""``CompiledTaskStack.serves``: a stack serves a task list only while what it was built from is
unchanged (the objects, the task an observer wraps, each site and each column list), whatever a
step changes of the tasks' targets and gains (those the stack copies in at every step)."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
from dynamics_reference import random_minimal_state
from test_compiled_tasks import _task_set
from test_wbc import _load

from controllers.low_level.disturbance_tasks import DisturbanceRejectingTask
from controllers.low_level.task_qp import QPSettings, TaskQP
from controllers.low_level.task_stack import structure, unwrap
from controllers.low_level.tasks import FramePositionTask, PostureTask
from wip_gym.robot_model import RobotModel


def _structures(tasks: list[object]) -> list[tuple[object, ...]]:
    return [(id(task), id(unwrap(task)[0]), *structure(unwrap(task)[0])) for task in tasks]


def test_serves_follows_the_structure() -> None:
    robot = RobotModel(_load("krang"))
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(5))))
    tasks = _task_set(robot, observed=True)
    low, high = robot.model.actuator_ctrlrange.T.copy()
    qp = TaskQP(robot, low, high, QPSettings())
    qp.assemble(robot, None, tasks)
    stack, kernel = qp._stack, qp.kernel
    assert stack is not None and kernel is not None
    built = _structures(tasks)

    def agrees(candidate: list[object]) -> bool:
        result = stack.serves(robot, kernel, candidate, ())
        assert result == (_structures(candidate) == built)
        return result

    assert agrees(list(tasks))
    # targets, gains and weights may change every step
    posture = next(t for t in tasks if isinstance(t, PostureTask))
    posture.target = posture.target + 0.1
    posture.kp = 3.0
    posture.joint_weights = posture.joint_weights * 2.0
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
    # another robot or kernel, extra constraints
    assert not stack.serves(RobotModel(robot.model), kernel, tasks, ())
    assert not stack.serves(robot, copy.copy(kernel), tasks, ())
    assert not stack.serves(robot, kernel, tasks, [object()])
