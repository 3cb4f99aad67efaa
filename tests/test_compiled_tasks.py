"""The compiled task rows (``controllers.low_level.compiled_tasks`` via ``task_stack``) against
the task objects they were written from, and their rotation helpers against MuJoCo's.

On random states of both robots, on and off the rolling manifold (the closed loop's measured
states leave it by contact compliance), with every task kind, two hand sites, and the
disturbance observers run over consecutive steps so that their memory evolves: ``J``,
``xdd*``, ``Jdot nu`` and the weights agree to 1e-12 of each array's scale."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from dynamics_reference import random_minimal_state
from test_wbc import _load, _realistic_tasks

from controllers.low_level import compiled_tasks as ct
from controllers.low_level.disturbance_tasks import DisturbanceRejectingTask, ObserverSettings
from controllers.low_level.motion_probe import MotionProbe
from controllers.low_level.task_qp import QPSettings, TaskQP
from controllers.low_level.task_stack import CompiledTaskStack, supports
from controllers.low_level.tasks import (
    FrameOrientationTask,
    FramePositionTask,
    Task,
    ThetaTask,
    rotation_error,
    site_in_axle_frame,
)
from wip_gym.robot_model import RobotModel


def _close(actual: np.ndarray, expected: np.ndarray, tol: float = 1e-12) -> None:
    scale = max(1.0, float(np.abs(expected).max())) if expected.size else 1.0
    np.testing.assert_allclose(actual, expected, rtol=0.0, atol=tol * scale)


def _random_rotation(rng: np.random.Generator, angle: float | None = None) -> np.ndarray:
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    quat = np.zeros(4)
    mujoco.mju_axisAngle2Quat(quat, axis, rng.uniform(0, np.pi) if angle is None else angle)
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, quat)
    return R.reshape(3, 3)


def test_rotation_helpers_equal_mujoco() -> None:
    rng = np.random.default_rng(3)
    branches = set()
    # small, generic and near-pi angles reach every branch of mju_mat2Quat
    for angle in [None] * 200 + [1e-9, 1e-4, np.pi - 1e-3, np.pi - 1e-7, np.pi] * 20:
        R = _random_rotation(rng, angle)
        expected = np.zeros(4)
        mujoco.mju_mat2Quat(expected, R.reshape(-1))
        ours = ct.mat2quat(R)
        np.testing.assert_allclose(ours, expected, rtol=0, atol=1e-15)
        trace = np.trace(R)
        branches.add(0 if trace > 0 else 1 + int(np.argmax(np.diag(R))))
        velocity = np.zeros(3)
        mujoco.mju_quat2Vel(velocity, expected, 1.0)
        np.testing.assert_allclose(ct.quat2vel(expected), velocity, rtol=0, atol=1e-15)
        target = _random_rotation(rng)
        np.testing.assert_allclose(
            ct.rotation_error(R, target), rotation_error(R, target), rtol=0, atol=1e-15
        )
    assert branches == {0, 1, 2, 3}


def _task_set(robot: RobotModel, observed: bool) -> list[Task]:
    """The controller's task kinds on the ``ee`` site, plus a position and an orientation
    task on a second site (Krang's right hand), the frame tasks optionally observed."""
    tasks = _realistic_tasks(robot)
    second = mujoco.mj_name2id(robot.model, mujoco.mjtObj.mjOBJ_SITE, "ee_right")
    if second >= 0:
        position, rotation, _, _ = site_in_axle_frame(robot, second)
        tasks += [
            FramePositionTask(second, position + 0.01, np.array([0.0, 1.0, 10.0]), 750.0, 250.0),
            FrameOrientationTask(
                second, rotation @ _random_rotation(np.random.default_rng(1), 0.1)
            ),
        ]
    if not observed:
        return tasks
    settings = ObserverSettings(dt=1e-3, bandwidth=30.0, bound=5.0)
    return [
        DisturbanceRejectingTask(task, settings)
        if isinstance(task, FramePositionTask | FrameOrientationTask)
        else task
        for task in tasks
    ]


def _python_rows(robot: RobotModel, probe: MotionProbe, tasks: list[Task]) -> tuple:
    J = np.vstack([task.jacobian(robot) for task in tasks])
    target = np.concatenate([task.reference_acceleration(robot) for task in tasks])
    w = np.concatenate([task.weights() for task in tasks])
    probe.update(robot)
    jdot = np.concatenate([task.jdot_nu(probe) for task in tasks])
    return J, target, jdot, w


@pytest.mark.parametrize("name", ["krang", "planar7"])
@pytest.mark.parametrize("observed", [False, True])
def test_compiled_rows_equal_the_task_objects(name: str, observed: bool) -> None:
    robot = RobotModel(_load(name))
    reference_robot = RobotModel(robot.model)
    rng = np.random.default_rng(11)
    q, nu = random_minimal_state(robot, rng)
    robot.update(*robot.full_state(q, nu))
    reference_robot.update(*robot.full_state(q, nu))
    # two copies of the same tasks: one run compiled, one by the objects
    compiled_tasks, python_tasks = _task_set(robot, observed), _task_set(reference_robot, observed)
    assert supports(compiled_tasks)
    stack = CompiledTaskStack(robot, MotionProbe(robot), compiled_tasks)
    probe = MotionProbe(reference_robot)
    rows = stack.rows
    J, target, jdot, w = (
        np.zeros((rows, robot.layout.n_min)),
        np.zeros(rows),
        np.zeros(rows),
        np.zeros(rows),
    )
    for step in range(12):
        # a trajectory of nearby states, every other one off the manifold
        q = q + 1e-3 * nu
        nu = nu + 0.05 * rng.normal(size=nu.shape)
        qpos, qvel = robot.full_state(q, nu)
        if step % 2:
            qpos = qpos + 1e-5 * rng.normal(size=qpos.shape)
            qvel = qvel + 2e-3 * rng.normal(size=qvel.shape)
            if not robot.layout.planar:
                qpos[3:7] /= np.linalg.norm(qpos[3:7])
        robot.update(qpos, qvel)
        reference_robot.update(qpos, qvel)
        if isinstance(compiled_tasks[0], ThetaTask):
            for tasks in (compiled_tasks, python_tasks):
                tasks[0].theta_d = robot.theta + 0.01 * step  # a moving target, read every step
        stack.fill(robot, J, target, jdot, w)
        expected = _python_rows(reference_robot, probe, python_tasks)
        for ours, theirs in zip((J, target, jdot, w), expected, strict=True):
            _close(ours, theirs)
    if observed:
        memories = [t.memory for t in compiled_tasks if isinstance(t, DisturbanceRejectingTask)]
        references = [t.memory for t in python_tasks if isinstance(t, DisturbanceRejectingTask)]
        assert any(np.abs(m[0]).max() > 1e-3 for m in references)  # the estimates moved
        for ours, theirs in zip(memories, references, strict=True):
            _close(ours, theirs)


def test_task_qp_compiled_and_python_paths_solve_alike() -> None:
    robot = RobotModel(_load("krang"))
    low, high = robot.model.actuator_ctrlrange.T.copy()
    compiled = TaskQP(robot, low, high, QPSettings())
    python = TaskQP(robot, low, high, QPSettings(compiled_tasks=False))
    rng = np.random.default_rng(5)
    for _ in range(5):
        robot.update(*robot.full_state(*random_minimal_state(robot, rng)))
        tasks = _realistic_tasks(robot)
        a, b = compiled.solve(robot, None, tasks), python.solve(robot, None, tasks)
        assert compiled._stack is not None and compiled._stack.tasks == tasks
        _close(a.actuators, b.actuators, 1e-9)
        _close(a.qdd, b.qdd, 1e-9)
