"""The low level's one-call step (``controllers.low_level.compiled_step``), the declared tables of
arrays it reads (``wip_gym.array_table``) and the task QP's two paths.

The one call runs the task objects' and the kernel's own arithmetic: its rows equal the
readable path's to 1e-12 of their scale (``tests/test_compiled_tasks.py`` tests each kind), and
its kernel buffers equal, to the bit, a kernel run on its rows; the solutions equal the
readable path's to 1e-9. The table is built again whenever what it points at is made anew, and
the robot model's arrays in it are written in place."""

from __future__ import annotations

import copy
import dataclasses
import pickle

import numpy as np
import pytest
from dynamics_reference import random_minimal_state
from test_compiled_tasks import _task_set
from test_wbc import _limits, _load, _realistic_tasks

from controllers.low_level.compiled_tasks import STEP
from controllers.low_level.kernel import KERNEL, LowLevelKernel
from controllers.low_level.task_qp import QPSettings, TaskQP
from controllers.low_level.task_stack import CompiledTaskStack
from wip_gym.array_table import (
    FLOAT_MATRIX,
    FLOAT_VECTOR,
    INT_VECTOR,
    ArrayTable,
    TableSpec,
    field_offsets,
    float_cube,
    float_matrix,
    float_vector,
    int_matrix,
    int_vector,
)
from wip_gym.robot_model import RobotModel

_ROWS = ("J", "target", "jdot_nu", "w")
_BUFFERS = ("T", "b", "H", "g", "C", "lower", "upper", "x", "calA", "Ph", "E", "e")


def _pair(robot: RobotModel) -> tuple[TaskQP, TaskQP]:
    """The compiled path and the readable one, on their own torque-limit arrays."""
    low, high = robot.model.actuator_ctrlrange.T.copy()
    compiled = TaskQP(robot, low, high, QPSettings())
    readable = TaskQP(robot, low.copy(), high.copy(), QPSettings(compiled_tasks=False))
    return compiled, readable


def _close(actual: np.ndarray, expected: np.ndarray, tol: float) -> None:
    scale = max(1.0, float(np.abs(expected).max())) if expected.size else 1.0
    np.testing.assert_allclose(actual, expected, rtol=0.0, atol=tol * scale)


def _assert_same_step(compiled: TaskQP, readable: TaskQP, robot: RobotModel) -> None:
    """The rows to 1e-12 and what the kernel makes of them to 1e-9 (the minimiser ``x`` aside:
    ``H`` is regularised by only 1e-6, and amplifies the rows' last bits), and the compiled
    call's kernel buffers to the bit as a kernel run on its own rows (the readable path's
    kernel, on those rows)."""
    one, two = compiled.kernel, readable.kernel
    assert one is not None and two is not None
    for name in (*_ROWS, *_BUFFERS):
        if name != "x":
            _close(getattr(one, name), getattr(two, name), 1e-12 if name in _ROWS else 1e-9)
    rows = [getattr(one, name).copy() for name in _ROWS]
    feasible = two.run(robot.A, robot.h, *rows, robot.q, robot.nu)
    for name in _BUFFERS:
        np.testing.assert_array_equal(getattr(one, name), getattr(two, name), name)
    assert feasible == compiled._feasible


@pytest.mark.parametrize("name", ["krang", "planar7"])
@pytest.mark.parametrize("observed", [False, True])
def test_the_compiled_step_equals_the_readable_one(name: str, observed: bool) -> None:
    robot = RobotModel(_load(name))
    compiled, readable = _pair(robot)
    rng = np.random.default_rng(21)
    q, nu = random_minimal_state(robot, rng)
    robot.update(*robot.full_state(q, nu))
    tasks_one, tasks_two = _task_set(robot, observed), _task_set(robot, observed)
    for step in range(6):
        # consecutive nearby states (the observers' memory evolves), then a far one
        if step == 5:
            q, nu = random_minimal_state(robot, rng)
        robot.update(*robot.full_state(q + 1e-3 * step * nu, nu + 0.05 * step))
        compiled.assemble(robot, None, tasks_one)
        readable.assemble(robot, None, tasks_two)
        assert compiled.compiled and not readable.compiled
        _assert_same_step(compiled, readable, robot)
        if observed:
            for one, two in zip(tasks_one, tasks_two, strict=True):
                if hasattr(one, "memory"):
                    _close(one.memory, two.memory, 1e-12)  # type: ignore[attr-defined]
        a, b = compiled.solve(robot, None, tasks_one), readable.solve(robot, None, tasks_two)
        assert (a.solved, a.iterations == 0) == (b.solved, b.iterations == 0)
        for field in ("qdd", "nu_dot", "generalized", "actuators"):
            _close(getattr(a, field), getattr(b, field), 1e-9)


@pytest.mark.parametrize("name", ["krang", "planar7"])
def test_solve_alone_takes_the_common_case(name: str) -> None:
    """``solve`` without an ``assemble`` before it, step after step (the control loop's use):
    once ProxQP is warm, its common case (one compiled call, the solution from the kernel's
    buffers, computed in that call) returns what the readable path returns, with the same
    bookkeeping, and what the kernel's own solution terms give, to the bit."""
    robot = RobotModel(_load(name))
    low, high = _limits(robot)
    compiled = TaskQP(robot, low, high, QPSettings())
    readable = TaskQP(robot, low.copy(), high.copy(), QPSettings(compiled_tasks=False))
    # a still state where no constraint binds (test_task_qp_shortcut), then small moves
    q, nu = random_minimal_state(robot, np.random.default_rng(500))
    nu[:] = 0.0
    robot.update(*robot.full_state(q, nu))
    tasks_one, tasks_two = _realistic_tasks(robot), _realistic_tasks(robot)
    drift = 1e-3 * np.random.default_rng(7).standard_normal(len(q))
    shortcuts = 0
    for step in range(8):
        robot.update(*robot.full_state(q + step * drift, drift))
        a, b = compiled.solve(robot, None, tasks_one), readable.solve(robot, None, tasks_two)
        assert compiled.compiled and not readable.compiled
        assert compiled._terms_ready == compiled._feasible
        assert compiled.proxqp_calls == readable.proxqp_calls
        assert (a.solved, a.iterations == 0) == (b.solved, b.iterations == 0)
        for field in ("qdd", "nu_dot", "generalized", "actuators"):
            _close(getattr(a, field), getattr(b, field), 1e-9)
        if a.iterations == 0:
            shortcuts += 1
            assert compiled._last_actuators is a.actuators
            c = compiled.solution_for(a.qdd.copy(), 0)
            for field in ("nu_dot", "generalized", "actuators"):
                np.testing.assert_array_equal(getattr(a, field), getattr(c, field), field)
    assert shortcuts >= 5  # the first step goes to ProxQP; the rest take the common case


def test_the_table_follows_new_torque_limits_and_tasks() -> None:
    robot = RobotModel(_load("krang"))
    compiled, readable = _pair(robot)
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(22))))
    tasks = _realistic_tasks(robot)
    compiled.assemble(robot, None, tasks)
    stack = compiled._stack
    assert stack is not None
    first = stack.table
    # limits changed in place: read through the same table
    compiled.torque_low[:] *= 0.5
    readable.torque_low[:] *= 0.5
    compiled.assemble(robot, None, tasks)
    readable.assemble(robot, None, tasks)
    assert compiled._stack is stack and stack.table is first
    _assert_same_step(compiled, readable, robot)
    # limits replaced by new arrays: a new kernel, so a new stack and table
    compiled.torque_high = compiled.torque_high * 0.25
    readable.torque_high = readable.torque_high * 0.25
    compiled.assemble(robot, None, tasks)
    readable.assemble(robot, None, tasks)
    assert compiled._stack is not stack
    _assert_same_step(compiled, readable, robot)
    # another task list of the same rows (new task objects): a new stack
    stack = compiled._stack
    again = _realistic_tasks(robot)
    compiled.assemble(robot, None, again)
    readable.assemble(robot, None, again)
    assert compiled._stack is not stack and compiled._stack is not None
    table = compiled._stack.table
    assert table.arrays[STEP.index.parameters] is compiled._stack.parameters
    _assert_same_step(compiled, readable, robot)
    # another task list of other rows: a new kernel with its row buffers, a new stack
    kernel = compiled.kernel
    fewer = tasks[:-1]
    compiled.assemble(robot, None, fewer)
    readable.assemble(robot, None, fewer)
    assert compiled.kernel is not kernel and compiled._stack is not None
    assert compiled._stack.table.arrays[STEP.index.J] is compiled.kernel.J  # type: ignore[union-attr]
    _assert_same_step(compiled, readable, robot)


def test_the_robot_arrays_in_the_table_are_written_in_place() -> None:
    """The table holds ``q``, ``nu``, ``J_tf``, ``Jdot_tf nu`` and the origin's Jacobian of
    one ``RobotModel``: an update must write them, not replace them."""
    robot = RobotModel(_load("krang"))
    rng = np.random.default_rng(23)
    robot.update(*robot.full_state(*random_minimal_state(robot, rng)))

    def arrays() -> list[np.ndarray]:
        return [robot.q, robot.nu, robot.J_tf, robot.Jdot_tf_nu, *robot.update_buffers().values()]

    held = arrays()
    before = [a.copy() for a in held]
    robot.update(*robot.full_state(*random_minimal_state(robot, rng)))
    after = arrays()
    assert all(a is b for a, b in zip(held, after, strict=True))
    # each changed with the state, but the origin's Jacobian (the free joint's translation: I)
    changed = [not np.array_equal(a, b) for a, b in zip(before, after, strict=True)]
    assert changed[:-1] == [True] * (len(changed) - 1)
    assert list(robot.update_buffers())[-1] == "origin_jac"


@pytest.mark.parametrize("copier", [copy.deepcopy, lambda qp: pickle.loads(pickle.dumps(qp))])
def test_a_copied_task_qp_builds_its_own_table(copier: object) -> None:
    robot = RobotModel(_load("planar7"))
    one, _ = _pair(robot)
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(24))))
    one.assemble(robot, None, _realistic_tasks(robot))
    clone = copier(one)  # type: ignore[operator]
    assert clone._stack is None
    # the kernel's table points at the copy's own buffers
    assert clone.kernel._table.rows[KERNEL.index.H, 0] == clone.kernel.H.ctypes.data
    assert clone.kernel._table.rows[KERNEL.index.H, 0] != one.kernel._table.rows[KERNEL.index.H, 0]
    # (stepping a copied controller on its own data: test_compiled_tasks.py's
    # test_a_copied_controller_steps_on_its_own_data)
    with pytest.raises(TypeError, match="addresses"):
        copy.deepcopy(one._stack.table)
    with pytest.raises(TypeError, match="addresses"):
        pickle.dumps(one._stack.table)


@pytest.mark.parametrize("copier", [copy.deepcopy, lambda qp: pickle.loads(pickle.dumps(qp))])
def test_a_copied_task_qp_solves_by_proxqp(copier: object) -> None:
    """A copy of a task QP whose ProxQP has run solves by ProxQP too (the solver object does not
    survive a pickle: it pickles empty, and an update of it crashed the process): the same
    torques as the original's, to ProxQP's tolerance; and it keeps trying the unconstrained
    minimiser first where the original does."""
    robot = RobotModel(_load("planar7"))
    low, high = robot.model.actuator_ctrlrange.T.copy()
    qp = TaskQP(robot, low, high, QPSettings(unconstrained_first=False))
    rng = np.random.default_rng(26)
    robot.update(*robot.full_state(*random_minimal_state(robot, rng)))
    tasks = _realistic_tasks(robot)
    first = qp.solve(robot, None, tasks)
    assert first.solved and first.iterations > 0 and qp._qp is not None
    clone_robot, clone, clone_tasks = copier((robot, qp, tasks))  # type: ignore[operator]
    assert clone._qp is None
    state = robot.full_state(*random_minimal_state(robot, rng))
    robot.update(*state)
    clone_robot.update(*state)
    original, copied = qp.solve(robot, None, tasks), clone.solve(clone_robot, None, clone_tasks)
    assert original.solved and copied.solved and copied.iterations > 0
    scale = float(np.abs(original.actuators).max())
    np.testing.assert_allclose(copied.actuators, original.actuators, rtol=0.0, atol=1e-6 * scale)
    # with the shortcut on, a copy made after ProxQP's first solve tries the unconstrained
    # minimiser first, as the original does: the same torques to the bit (a state near rest,
    # where that minimiser meets every constraint)
    q, nu = random_minimal_state(robot, rng)
    state = robot.full_state(0.1 * q, 0.1 * nu)
    robot.update(*state)
    tasks = _realistic_tasks(robot)
    shortcut = TaskQP(robot, low, high, QPSettings())
    assert shortcut.solve(robot, None, tasks).iterations > 0  # the first step: ProxQP
    clone_robot, clone, clone_tasks = copier((robot, shortcut, tasks))  # type: ignore[operator]
    robot.update(*state)
    clone_robot.update(*state)
    original = shortcut.solve(robot, None, tasks)
    copied = clone.solve(clone_robot, None, clone_tasks)
    assert shortcut.proxqp_calls == clone.proxqp_calls == 1  # neither called ProxQP again
    np.testing.assert_array_equal(copied.actuators, original.actuators)


def test_the_table_reads_and_writes_the_arrays_it_was_built_from() -> None:
    rng = np.random.default_rng(25)
    arrays = [
        rng.normal(size=4),
        rng.normal(size=(3, 5)),
        rng.normal(size=(2, 3, 4)),
        np.arange(7, dtype=np.int64),
        np.arange(12, dtype=np.int64).reshape(3, 4),
        np.zeros(0),
    ]
    table = ArrayTable(arrays, ["v", "m", "c", "iv", "im", "empty"])
    # it keeps the very arrays (alive while it is), not copies
    assert all(a is b for a, b in zip(table.arrays, arrays, strict=True))
    rows = table.rows
    np.testing.assert_array_equal(float_vector(rows[0]), arrays[0])
    np.testing.assert_array_equal(float_matrix(rows[1]), arrays[1])
    np.testing.assert_array_equal(float_cube(rows[2]), arrays[2])
    np.testing.assert_array_equal(int_vector(rows[3]), arrays[3])
    np.testing.assert_array_equal(int_matrix(rows[4]), arrays[4])
    assert float_vector(rows[5]).shape == (0,)
    view = float_matrix(rows[1])
    view[2, 4] = 123.0  # a view: written through
    assert arrays[1][2, 4] == 123.0
    with pytest.raises(ValueError, match="another kind"):
        float_matrix(rows[0])
    with pytest.raises(ValueError, match="another kind"):
        int_vector(rows[0])


@pytest.mark.parametrize(
    ("array", "message"),
    [
        (np.zeros(3, dtype=np.float32), "float32 of 1 dimensions"),
        (np.zeros((2, 2, 2, 2)), "float64 of 4 dimensions"),
        (np.zeros((2, 2, 2), dtype=np.int64), "int64 of 3 dimensions"),
        (np.zeros((4, 4))[:, 1], "not C-contiguous"),
        ([1.0, 2.0], "is a list"),
    ],
)
def test_the_table_refuses_what_compiled_code_cannot_view(array: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        ArrayTable([np.zeros(2), array], ["fine", "bad"])  # type: ignore[list-item]


def test_a_stack_refuses_a_kernel_of_other_rows() -> None:
    robot = RobotModel(_load("krang"))
    one, _ = _pair(robot)
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(26))))
    tasks = _realistic_tasks(robot)
    one.assemble(robot, None, tasks)
    assert one.kernel is not None
    other = LowLevelKernel(dataclasses.replace(one.kernel.layout, rows=one.kernel.layout.rows + 1))
    with pytest.raises(ValueError, match="rows"):
        CompiledTaskStack(robot, one.motion, other, tasks)


def test_a_declared_table_checks_its_arrays_and_folds_its_indices() -> None:
    """A ``TableSpec`` gives each name its row (a base's first), builds the table from arrays by
    name and refuses a missing, unknown or other-kind array, or a name declared twice;
    ``field_offsets`` lays out a vector of fields."""
    base = TableSpec("base", (("a", FLOAT_VECTOR), ("b", INT_VECTOR)))
    spec = TableSpec("more", (("c", FLOAT_MATRIX),), base=base)
    assert spec.names == ("a", "b", "c") and spec.index.b == base.index.b == 1
    assert spec.index.c == 2
    arrays = {"a": np.zeros(3), "b": np.arange(2, dtype=np.int64), "c": np.ones((2, 2))}
    table = spec.table(arrays)
    np.testing.assert_array_equal(float_matrix(table.rows[spec.index.c]), arrays["c"])
    with pytest.raises(ValueError, match=r"missing \['c'\], unknown \['d'\]"):
        spec.table({"a": arrays["a"], "b": arrays["b"], "d": arrays["c"]})
    with pytest.raises(ValueError, match="'b' is float64 of 1 dimensions, declared int64"):
        spec.table({**arrays, "b": np.zeros(2)})
    with pytest.raises(ValueError, match=r"fields \['a'\] declared twice"):
        TableSpec("twice", (("a", FLOAT_VECTOR),), base=base)
    offsets, size = field_offsets("v", (("x", 1), ("axle", 3), ("y", 1)))
    assert (offsets.x, offsets.axle, offsets.y, size) == (0, 1, 4, 5)
    # the one-call step's table begins with the kernel's: kernel_step reads either
    assert STEP.names[: len(KERNEL.names)] == KERNEL.names


@pytest.mark.parametrize("name", ["krang", "planar7"])
def test_the_robot_updates_properties_are_copies_of_its_table(name: str) -> None:
    """``RobotModel.update`` writes its table's buffers (``minimal_kernels.UPDATE``): the
    scalars, the WIPM state and the properties are theirs, and the properties are copies that
    stay as they were after the next update."""
    robot = RobotModel(_load(name))
    rng = np.random.default_rng(27)
    kept = None
    for dynamics in (True, False, True):
        qpos, qvel = robot.full_state(*random_minimal_state(robot, rng))
        robot.update(qpos, qvel, dynamics=dynamics)
        buffers = robot.update_buffers()
        psi, psid, c, s, mass, theta, thetad, x, xd, axle_x, axle_y = buffers[
            "robot_scalars"
        ].tolist()
        assert (robot.theta, robot.thetad, robot.body_mass, robot.psi) == (theta, thetad, mass, psi)
        np.testing.assert_array_equal(
            robot.wipm_state(),
            [theta, thetad, x, xd]
            if robot.layout.planar
            else [x, psi, theta, xd, psid, thetad, axle_x, axle_y],
        )
        np.testing.assert_array_equal(robot.J_theta, buffers["J_theta"])
        np.testing.assert_array_equal(
            robot.heading_rotation, [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
        )
        assert robot.has_dynamics == dynamics
        if dynamics:
            np.testing.assert_array_equal(robot.A, buffers["A"])
            np.testing.assert_array_equal(robot.h, buffers["h"])
            assert robot.A is robot.A and robot.A is not buffers["A"]  # one copy per update
            if kept is not None:
                # what a caller kept from an earlier update is as it was
                for array, value in zip(kept[0], kept[1], strict=True):
                    np.testing.assert_array_equal(array, value)
            kept_arrays = (
                robot.A,
                robot.h,
                robot.B,
                robot.com,
                robot.J_theta,
                robot.heading_rotation,
            )
            kept = (kept_arrays, [a.copy() for a in kept_arrays])
        else:
            with pytest.raises(RuntimeError, match="dynamics=False"):
                robot.A  # noqa: B018


def test_the_one_call_step_needs_the_dynamics() -> None:
    robot = RobotModel(_load("krang"))
    one, _ = _pair(robot)
    qpos, qvel = robot.full_state(*random_minimal_state(robot, np.random.default_rng(28)))
    robot.update(qpos, qvel)
    tasks = _realistic_tasks(robot)
    one.assemble(robot, None, tasks)
    robot.update(qpos, qvel, dynamics=False)
    with pytest.raises(RuntimeError, match="dynamics=False"):
        one.assemble(robot, None, tasks)


@pytest.mark.parametrize("env_id", ["wip_gym/PlanarTray-v0", "wip_gym/KrangTray-v0"])
def test_a_closed_loop_takes_the_compiled_path_as_the_readable_one(env_id: str) -> None:
    """The default controller (hand observers on, the MPC every tenth step) in closed loop, and
    a second one on the readable QP path fed the same observations: the same actions to 1e-9
    of their scale over 150 steps, every one by the QP's shortcut, the compiled one on the
    stack it built at reset."""
    import gymnasium as gym

    import wip_gym  # noqa: F401
    from controllers.hierarchical import HierarchicalConfig, HierarchicalController

    env = gym.make(env_id)
    obs, info = env.reset(seed=4)
    policies = [
        HierarchicalController.for_env(env, HierarchicalConfig(qp=QPSettings(compiled_tasks=on)))
        for on in (True, False)
    ]
    for policy in policies:
        policy.reset(obs, info)
    fast, readable = policies
    calls, stack = fast.qp.proxqp_calls, fast.qp._stack
    for _ in range(150):
        action = fast(obs)
        _close(readable(obs), action, 1e-9)
        obs, *_ = env.step(action)
    assert fast.qp.proxqp_calls == calls and fast.qp._stack is stack  # shortcut, one stack
    assert fast.qp.compiled and not readable.qp.compiled
    env.close()
    for policy in policies:
        policy.high_level.close()


def test_the_heading_before_any_update_is_the_identity() -> None:
    robot = RobotModel(_load("krang"))
    np.testing.assert_array_equal(robot.heading_rotation, np.eye(3))
    assert not robot.heading_rotation.flags.writeable
