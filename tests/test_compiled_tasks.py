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
from controllers.low_level import tasks as tasks_module
from controllers.low_level.compiled_tasks import ITEM
from controllers.low_level.disturbance_tasks import (
    ADVANCED_IN_MEMORY,
    DisturbanceRejectingTask,
    ObserverSettings,
)
from controllers.low_level.motion_probe import MotionProbe
from controllers.low_level.task_qp import QPSettings, TaskQP
from controllers.low_level.task_stack import supports
from controllers.low_level.tasks import (
    FrameOrientationTask,
    FramePositionTask,
    PostureTask,
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
    assert supports(compiled_tasks, (), robot.layout.planar)
    compiled, python = _paths(robot)
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
        compiled.assemble(robot, None, compiled_tasks)
        assert compiled.compiled
        expected = _python_rows(reference_robot, MotionProbe(reference_robot), python_tasks)
        kernel = compiled.kernel
        rows = (kernel.J, kernel.target, kernel.jdot_nu, kernel.w)
        for ours, theirs in zip(rows, expected, strict=True):
            _close(ours, theirs)
    if observed:
        memories = [t.memory for t in compiled_tasks if isinstance(t, DisturbanceRejectingTask)]
        references = [t.memory for t in python_tasks if isinstance(t, DisturbanceRejectingTask)]
        assert any(np.abs(m[0]).max() > 1e-3 for m in references)  # the estimates moved
        for ours, theirs in zip(memories, references, strict=True):
            _close(ours, theirs)


def test_every_stock_task_has_the_one_pd_law(monkeypatch: pytest.MonkeyPatch) -> None:
    """The paper's PD law ``xdd_d - Kp e - Kv e_dot`` is one function, ``pd_acceleration``:
    its compiled form gives its bits, every stock task's reference acceleration is its value
    for the task's error and rate error, and a law changed there reaches every task (the
    compiled rows call the same function: ``test_compiled_rows_equal_the_task_objects``)."""
    rng = np.random.default_rng(5)
    for _ in range(20):
        ff, e, ed, kp, kv = rng.normal(size=5) * 10.0
        assert ct._pd(ff, e, ed, kp, kv) == ct.pd_acceleration(ff, e, ed, kp, kv)
        assert ct.pd_acceleration(ff, e, ed, kp, kv) == ff - kp * e - kv * ed
    robot = RobotModel(_load("krang"))
    q, nu = random_minimal_state(robot, rng)
    robot.update(*robot.full_state(q, nu))
    tasks = _task_set(robot, observed=False)
    assert {type(t).__name__ for t in tasks} == {
        "ThetaTask", "SpinTask", "FramePositionTask", "FrameOrientationTask", "PostureTask"
    }  # fmt: skip
    for task in tasks:
        if isinstance(task, PostureTask):  # every task off its target
            task.target = task.target + 0.01
        elif isinstance(task, FrameOrientationTask):
            task.target = task.target @ _random_rotation(rng, 0.1)
    before = [task.reference_acceleration(robot) for task in tasks]
    calls = []

    def law(feedforward: object, error: object, rate_error: object, kp: float, kv: float) -> object:
        calls.append(kp)
        return ct.pd_acceleration(feedforward, error, rate_error, 2.0 * kp, kv)

    monkeypatch.setattr(tasks_module, "pd_acceleration", law)
    after = [task.reference_acceleration(robot) for task in tasks]
    assert len(calls) == len(tasks)
    for task, old, new in zip(tasks, before, after, strict=True):
        # doubling Kp moves each reference by -Kp e: the error term went through the law
        error = task.error(robot)
        assert np.abs(error).max() > 1e-4
        _close(new - old, -task.kp * error, 1e-9 * max(1.0, float(np.abs(old).max())))


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
        assert compiled.compiled and not python.compiled and compiled._stack.tasks == tasks
        _close(a.actuators, b.actuators, 1e-9)
        _close(a.qdd, b.qdd, 1e-9)


def _paths(robot: RobotModel) -> tuple[TaskQP, TaskQP]:
    low, high = robot.model.actuator_ctrlrange.T.copy()
    return TaskQP(robot, low, high, QPSettings()), TaskQP(
        robot, low, high, QPSettings(compiled_tasks=False)
    )


def test_a_second_solve_at_one_state_does_not_advance_the_observers_again() -> None:
    """The observers' Python path memoises their command per state; the compiled path, asked
    twice at one state, gives the same rows the second time."""
    robot = RobotModel(_load("krang"))
    rng = np.random.default_rng(8)
    compiled, _ = _paths(robot)
    q, nu = random_minimal_state(robot, rng)
    robot.update(*robot.full_state(q, nu))
    tasks = _task_set(robot, observed=True)
    for step in range(3):
        robot.update(*robot.full_state(q + 1e-3 * step * nu, nu + 0.1 * step))
        first = compiled.solve(robot, None, tasks).actuators
        memory = compiled._stack.observer_memory.copy()
        again = compiled.solve(robot, None, tasks).actuators
        np.testing.assert_array_equal(again, first)
        np.testing.assert_array_equal(compiled._stack.observer_memory, memory)


def test_an_observer_advanced_by_the_compiled_path_gives_its_rows_to_the_python_path() -> None:
    """After a compiled step the observers are marked advanced at this state
    (``ADVANCED_IN_MEMORY``): asked by their Python path at the same state they return the
    command the compiled rows hold, to the bit, and do not advance; asked after the next
    update they advance again. And the other way round: an observer the Python path advanced
    at this state is not advanced again by the compiled step."""
    robot = RobotModel(_load("krang"))
    rng = np.random.default_rng(9)
    compiled, _ = _paths(robot)
    q, nu = random_minimal_state(robot, rng)
    tasks = _task_set(robot, observed=True)
    observed = [task for task in tasks if isinstance(task, DisturbanceRejectingTask)]
    assert len(observed) == 4
    before = None
    for step in range(4):
        robot.update(*robot.full_state(q + 1e-3 * step * nu, nu + 0.1 * step))
        compiled.solve(robot, None, tasks)
        stack = compiled._stack
        memory = stack.observer_memory.copy()
        if before is not None:  # the next update's step advanced every observer
            assert all(not np.array_equal(memory[i], before[i]) for i in range(len(observed)))
        before = memory
        for task in observed:
            assert robot.cache[task.cache_key] is ADVANCED_IN_MEMORY
        for k, task in enumerate(tasks):
            if task in observed:
                start = stack.items[k, ITEM.row]
                stop = start + stack.items[k, ITEM.rows]
                command = task.reference_acceleration(robot)
                np.testing.assert_array_equal(command, compiled.kernel.target[start:stop])
                assert task.reference_acceleration(robot) is command  # memoised from now on
        np.testing.assert_array_equal(stack.observer_memory, memory)  # nothing advanced
    # the Python path first at a new state: the compiled step then does not advance it again
    robot.update(*robot.full_state(q + 0.01 * nu, nu))
    first = observed[0].reference_acceleration(robot)
    memory = compiled._stack.observer_memory.copy()
    compiled.solve(robot, None, tasks)
    np.testing.assert_array_equal(compiled._stack.observer_memory[0], memory[0])
    assert not np.array_equal(compiled._stack.observer_memory[1], memory[1])  # the others did
    assert robot.cache[observed[0].cache_key] is first


def test_the_advanced_marker_survives_copies_and_follows_the_stack_that_owns_the_memory() -> None:
    """The marker is one object through a deep copy and a pickle (a copied controller's cache
    holds it), and an observer another stack has adopted since is memoised as its rows of the
    stack that advanced it: a Python-path QP at that state gets that stack's command, not the
    adopting stack's stale one."""
    import copy
    import pickle

    assert copy.deepcopy(ADVANCED_IN_MEMORY) is ADVANCED_IN_MEMORY
    assert pickle.loads(pickle.dumps(ADVANCED_IN_MEMORY)) is ADVANCED_IN_MEMORY
    robot = RobotModel(_load("krang"))
    q, nu = random_minimal_state(robot, np.random.default_rng(13))
    tasks = _task_set(robot, observed=True)
    first, python = _paths(robot)
    second, _ = _paths(robot)
    robot.update(*robot.full_state(q, nu))
    first.solve(robot, None, tasks)
    twin = copy.deepcopy(robot)
    observed = [(k, t) for k, t in enumerate(tasks) if isinstance(t, DisturbanceRejectingTask)]
    for _, task in observed:
        assert twin.cache[task.cache_key] is ADVANCED_IN_MEMORY
    second.solve(robot, None, tasks)  # a second stack: it adopts the observers' memory
    assert not first._stack.owns_its_observers() and second._stack.owns_its_observers()
    robot.update(*robot.full_state(q + 1e-3 * nu, nu + 0.1))
    first.solve(robot, None, tasks)  # advances its own memory, not the adopted one
    for k, task in observed:
        start = first._stack.items[k, ITEM.row]
        stop = start + first._stack.items[k, ITEM.rows]
        np.testing.assert_array_equal(
            task.reference_acceleration(robot), first.kernel.target[start:stop]
        )
    python.solve(robot, None, tasks)  # reads the memoised commands: no error, no advance


def test_a_step_keeps_its_stack_until_the_structure_changes() -> None:
    """Between steps where nothing structural changed, the task QP's compiled step keeps its
    stack (it copies the tasks' parameters in, a changed target or gain included); a task list
    changed in place, a posture task's columns changed in place, or new torque limits make a
    new stack, which solves as the readable path does."""
    robot = RobotModel(_load("krang"))
    compiled, python = _paths(robot)
    rng = np.random.default_rng(12)
    q, nu = random_minimal_state(robot, rng)
    tasks = _realistic_tasks(robot)

    def step(k: int) -> None:
        robot.update(*robot.full_state(q + 1e-3 * k * nu, nu))
        a, b = compiled.solve(robot, None, tasks), python.solve(robot, None, tasks)
        _close(a.actuators, b.actuators, 1e-9)

    step(0)
    stack = compiled._stack
    posture = next(t for t in tasks if isinstance(t, PostureTask))
    for k in range(1, 4):
        posture.target = posture.target + 0.01  # a parameter: copied in, same stack
        posture.kp = 10.0 + k
        step(k)
        assert compiled._stack is stack
    changes = [
        lambda: tasks.insert(0, tasks.pop()),  # the list, in place: the rows' order
        lambda: posture.columns.__setitem__(0, posture.columns[1]),  # in place
        lambda: setattr(compiled, "torque_high", compiled.torque_high * 0.5),
    ]
    for n, change in enumerate(changes):
        stack = compiled._stack
        change()
        python.torque_high = compiled.torque_high
        step(10 + n)
        assert compiled._stack is not stack  # built anew for the new structure
        stack = compiled._stack
        step(20 + n)
        assert compiled._stack is stack  # and kept again


def test_a_parameter_of_another_size_is_refused_by_name() -> None:
    """The per-step copy refuses a target of another size than the stack was built for (its
    rows read a fixed count), naming the task."""
    robot = RobotModel(_load("krang"))
    compiled, _ = _paths(robot)
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(15))))
    tasks = _realistic_tasks(robot)
    compiled.solve(robot, None, tasks)
    posture = next(t for t in tasks if isinstance(t, PostureTask))
    posture.target = np.append(posture.target, 0.0)
    with pytest.raises(ValueError, match="task 'posture'"):
        compiled.solve(robot, None, tasks)


def test_a_changed_site_or_columns_rebuilds_the_compiled_stack() -> None:
    robot = RobotModel(_load("krang"))
    compiled, python = _paths(robot)
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(9))))
    tasks = _realistic_tasks(robot)
    compiled.solve(robot, None, tasks)
    first_stack = compiled._stack
    right = mujoco.mj_name2id(robot.model, mujoco.mjtObj.mjOBJ_SITE, "ee_right")
    position = next(t for t in tasks if isinstance(t, FramePositionTask))
    position.site = right  # the other hand, same task object
    posture = tasks[-1]
    posture.columns = posture.columns[1:]  # one joint fewer, same task object
    posture.target, posture.joint_weights = posture.target[1:], posture.joint_weights[1:]
    a, b = compiled.solve(robot, None, tasks), python.solve(robot, None, tasks)
    assert compiled._stack is not first_stack
    _close(a.actuators, b.actuators, 1e-9)


def test_compiled_rows_on_an_oracle_model_with_the_cup() -> None:
    """A controller's oracle model is the env's own, cup and tray included (free bodies past
    the robot's joints): both paths run and agree."""
    import gymnasium as gym

    import wip_gym  # noqa: F401
    from controllers.policy import controller_model

    env = gym.make("wip_gym/KrangTray-v0")
    env.reset(seed=3)
    robot = RobotModel(controller_model(env, "oracle"))
    assert robot.model.nv > robot.layout.nv  # the cup's free joint
    compiled, python = _paths(robot)
    rng = np.random.default_rng(10)
    for _ in range(3):
        robot.update(*robot.full_state(*random_minimal_state(robot, rng)))
        tasks = _realistic_tasks(robot)
        a, b = compiled.solve(robot, None, tasks), python.solve(robot, None, tasks)
        assert compiled.compiled
        _close(a.actuators, b.actuators, 1e-9)
    env.close()


def test_read_only_or_strided_states_do_not_compile_the_update_again() -> None:
    from wip_gym.minimal_kernels import robot_update_at

    robot = RobotModel(_load("krang"))
    qpos, qvel = robot.full_state(*random_minimal_state(robot, np.random.default_rng(12)))
    robot.update(qpos, qvel)
    frozen = qpos.copy()
    frozen.flags.writeable = False
    strided = np.repeat(qvel, 2)[::2]
    robot.update(frozen, strided)
    # the update's one compiled signature (its table), whatever the caller passes or the robot
    assert len(robot_update_at.signatures) == 1
    reference = RobotModel(robot.model)
    reference.update(qpos, qvel)
    np.testing.assert_array_equal(robot.q, reference.q)
    np.testing.assert_array_equal(robot.A, reference.A)


def test_a_copied_controller_steps_on_its_own_data() -> None:
    """``copy.deepcopy`` of a stepping controller: the copy's compiled calls use its own MuJoCo
    data (views and addresses are made again), so it gives the original's next action and goes
    on after the original is gone."""
    import copy
    import gc

    import gymnasium as gym

    import wip_gym  # noqa: F401
    from controllers.hierarchical import HierarchicalController

    env = gym.make("wip_gym/PlanarTray-v0")
    obs, info = env.reset(seed=5)
    policy = HierarchicalController.for_env(env)
    policy.reset(obs, info)
    for _ in range(15):
        obs, *_ = env.step(policy(obs))
    twin = copy.deepcopy(policy)
    assert twin.robot.data is not policy.robot.data
    np.testing.assert_array_equal(twin(obs), policy(obs))
    del policy
    gc.collect()
    for _ in range(5):
        action = twin(obs)
        assert np.isfinite(action).all()
        obs, *_ = env.step(action)
    env.close()


def test_a_site_or_column_out_of_range_is_refused_by_name() -> None:
    """The compiled rows read sites and posture columns without bounds checks, and MuJoCo's
    Jacobians read past their arrays on a bad site id: both paths refuse an index out of
    range by the task's name, whether the task came so or was changed in place between steps;
    a negative column counts from the end, as in NumPy, on both paths; a negative site is
    refused (NumPy would take the last site, MuJoCo read before its arrays); a posture task
    needs one weight per column."""
    robot = RobotModel(_load("krang"))
    compiled, python = _paths(robot)
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(14))))
    tasks = _realistic_tasks(robot)
    compiled.solve(robot, None, tasks)
    posture = next(t for t in tasks if isinstance(t, PostureTask))
    n_min = robot.layout.n_min
    posture.columns[0] = n_min  # in place, between steps
    with pytest.raises(ValueError, match=r"task 'posture': columns \[\d+\] are not indices"):
        compiled.solve(robot, None, tasks)
    with pytest.raises(ValueError, match=r"task 'posture': columns \[\d+\] are not indices"):
        python.solve(robot, None, tasks)
    posture.columns[0] = -1  # the last coordinate, on both paths
    a, b = compiled.solve(robot, None, tasks), python.solve(robot, None, tasks)
    _close(a.actuators, b.actuators, 1e-9)
    posture.columns[0] = 3
    frame = next(t for t in tasks if isinstance(t, FramePositionTask))
    site = frame.site
    for bad in (robot.model.nsite, -1):
        frame.site = bad
        for qp in (compiled, python):
            with pytest.raises(ValueError, match=r"site -?\d+ is not one of the model's"):
                qp.solve(robot, None, tasks)
    frame.site = site
    # one weight for all the columns: broadcast on both paths, into a stack's arrays too
    weights = posture.joint_weights.copy()
    posture.joint_weights = np.array([2.0])
    a, b = compiled.solve(robot, None, tasks), python.solve(robot, None, tasks)
    _close(a.actuators, b.actuators, 1e-9)
    posture.joint_weights = weights
    # another number of weights: refused when a stack is built, and on the Python path
    fresh, _ = _paths(robot)
    posture.joint_weights = weights[1:]
    for qp in (fresh, python):
        with pytest.raises(ValueError, match=r"task 'posture': joint weights .*\(one per row"):
            qp.solve(robot, None, tasks)
