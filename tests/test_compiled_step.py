"""The low level's one-call step (``controllers.low_level.compiled_step``) and the table of
arrays it reads (``wip_gym.array_table``).

The one call runs the rows' and the kernel's own arithmetic, so it must equal the two calls to
the bit: on random states of both robots (observers advancing over consecutive steps), every
kernel buffer and the feasibility agree exactly. The table is built again whenever what it
points at is made anew, and the robot model's arrays in it are written in place."""

from __future__ import annotations

import copy
import dataclasses
import pickle

import numpy as np
import pytest
from dynamics_reference import random_minimal_state
from test_compiled_tasks import _task_set
from test_wbc import _limits, _load, _realistic_tasks

from controllers.low_level.compiled_step import ENTRIES
from controllers.low_level.task_qp import QPSettings, TaskQP
from wip_gym.array_table import (
    ArrayTable,
    float_cube,
    float_matrix,
    float_vector,
    int_matrix,
    int_vector,
)
from wip_gym.robot_model import RobotModel

_BUFFERS = ("T", "b", "H", "g", "C", "lower", "upper", "x", "calA", "Ph", "E", "e")


def _pair(robot: RobotModel) -> tuple[TaskQP, TaskQP]:
    low, high = robot.model.actuator_ctrlrange.T.copy()
    one = TaskQP(robot, low, high, QPSettings())
    two = TaskQP(robot, low.copy(), high.copy(), QPSettings(one_call=False))
    return one, two


def _assert_same_step(one: TaskQP, two: TaskQP) -> None:
    for name in _BUFFERS:
        np.testing.assert_array_equal(getattr(one.kernel, name), getattr(two.kernel, name), name)
    np.testing.assert_array_equal(one._J, two._J)
    np.testing.assert_array_equal(one._target, two._target)
    np.testing.assert_array_equal(one._bias, two._bias)
    np.testing.assert_array_equal(one._w, two._w)
    assert one._feasible == two._feasible


@pytest.mark.parametrize("name", ["krang", "planar7"])
@pytest.mark.parametrize("observed", [False, True])
def test_one_call_equals_the_two_calls_to_the_bit(name: str, observed: bool) -> None:
    robot = RobotModel(_load(name))
    one, two = _pair(robot)
    rng = np.random.default_rng(21)
    q, nu = random_minimal_state(robot, rng)
    robot.update(*robot.full_state(q, nu))
    tasks_one, tasks_two = _task_set(robot, observed), _task_set(robot, observed)
    for step in range(6):
        # consecutive nearby states (the observers' memory evolves), then a far one
        if step == 5:
            q, nu = random_minimal_state(robot, rng)
        robot.update(*robot.full_state(q + 1e-3 * step * nu, nu + 0.05 * step))
        one.assemble(robot, None, tasks_one)
        two.assemble(robot, None, tasks_two)
        assert one.compiled and two.compiled and one._table is not None and two._table is None
        _assert_same_step(one, two)
        if observed:
            np.testing.assert_array_equal(
                one._stack.observer_memory,  # type: ignore[union-attr]
                two._stack.observer_memory,  # type: ignore[union-attr]
            )
        # the solutions: on a shortcut step the one call's torques (computed in it) equal the
        # two calls' (solution_terms after them) to the bit; ProxQP (the first step, and any
        # with an active constraint) agrees to its tolerance (its SIMD sums may depend on the
        # buffers' alignment)
        a, b = one.solve(robot, None, tasks_one), two.solve(robot, None, tasks_two)
        assert (a.solved, a.iterations == 0) == (b.solved, b.iterations == 0)
        for field in ("qdd", "nu_dot", "generalized", "actuators"):
            if a.iterations == 0:
                np.testing.assert_array_equal(getattr(a, field), getattr(b, field), field)
            else:
                scale = max(1.0, float(np.abs(getattr(b, field)).max()))
                np.testing.assert_allclose(
                    getattr(a, field), getattr(b, field), rtol=0, atol=1e-9 * scale
                )


@pytest.mark.parametrize("name", ["krang", "planar7"])
def test_solve_alone_takes_the_common_case_and_equals_the_two_calls(name: str) -> None:
    """``solve`` without an ``assemble`` before it, step after step (the control loop's use):
    once ProxQP is warm, its common case (one compiled call, the solution from the kernel's
    buffers) returns what the two-call path returns, to the bit, with the same bookkeeping."""
    robot = RobotModel(_load(name))
    low, high = _limits(robot)
    one = TaskQP(robot, low, high, QPSettings())
    two = TaskQP(robot, low.copy(), high.copy(), QPSettings(one_call=False))
    # a still state where no constraint binds (test_task_qp_shortcut), then small moves
    q, nu = random_minimal_state(robot, np.random.default_rng(500))
    nu[:] = 0.0
    robot.update(*robot.full_state(q, nu))
    tasks_one, tasks_two = _realistic_tasks(robot), _realistic_tasks(robot)
    drift = 1e-3 * np.random.default_rng(7).standard_normal(len(q))
    shortcuts = 0
    for step in range(8):
        robot.update(*robot.full_state(q + step * drift, drift))
        a, b = one.solve(robot, None, tasks_one), two.solve(robot, None, tasks_two)
        assert one.compiled and one._table is not None and two._table is None
        _assert_same_step(one, two)
        assert one._terms_ready == one._feasible and one.proxqp_calls == two.proxqp_calls
        assert (a.solved, a.iterations == 0) == (b.solved, b.iterations == 0)
        if a.iterations == 0:
            shortcuts += 1
            for field in ("qdd", "nu_dot", "generalized", "actuators"):
                np.testing.assert_array_equal(getattr(a, field), getattr(b, field), field)
            assert one._last_actuators is a.actuators
    assert shortcuts >= 5  # the first step goes to ProxQP; the rest take the common case


def test_the_table_follows_new_torque_limits_row_buffers_and_tasks() -> None:
    robot = RobotModel(_load("krang"))
    one, two = _pair(robot)
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(22))))
    tasks = _realistic_tasks(robot)
    one.assemble(robot, None, tasks)
    first = one._table
    # limits changed in place: read through the same table
    one.torque_low[:] *= 0.5
    two.torque_low[:] *= 0.5
    one.assemble(robot, None, tasks)
    two.assemble(robot, None, tasks)
    assert one._table is first
    _assert_same_step(one, two)
    # limits replaced by new arrays: a new kernel, so a new table
    one.torque_high = one.torque_high * 0.25
    two.torque_high = two.torque_high * 0.25
    one.assemble(robot, None, tasks)
    two.assemble(robot, None, tasks)
    assert one._table is not first
    _assert_same_step(one, two)
    # another task list of the same rows (new task objects): a new stack, so a new table
    second = one._table
    again = _realistic_tasks(robot)
    one.assemble(robot, None, again)
    two.assemble(robot, None, again)
    assert one._table is not second
    assert one._table.arrays[ENTRIES.index("kinds")] is one._stack.kinds  # type: ignore[union-attr]
    _assert_same_step(one, two)
    # another task list of other rows: a new stack, new row buffers, a new table
    second = one._table
    fewer = tasks[:-1]
    one.assemble(robot, None, fewer)
    two.assemble(robot, None, fewer)
    assert one._table is not second
    assert one._table.arrays[list(one._table.names).index("J")] is one._J  # type: ignore[union-attr]
    _assert_same_step(one, two)


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
    assert clone._table is None and clone._stack is None
    # (stepping a copied controller on its own data: test_compiled_tasks.py's
    # test_a_copied_controller_steps_on_its_own_data)
    with pytest.raises(TypeError, match="addresses"):
        copy.deepcopy(one._table)
    with pytest.raises(TypeError, match="addresses"):
        pickle.dumps(one._table)


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


def test_the_step_table_refuses_a_kernel_of_other_rows() -> None:
    from controllers.low_level.compiled_step import step_table

    robot = RobotModel(_load("krang"))
    one, _ = _pair(robot)
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(26))))
    tasks = _realistic_tasks(robot)
    one.assemble(robot, None, tasks)
    other = dataclasses.replace(one.kernel.layout, rows=one.kernel.layout.rows + 1)
    from controllers.low_level.kernel import LowLevelKernel

    with pytest.raises(ValueError, match="rows"):
        step_table(
            one._stack,  # type: ignore[arg-type]
            LowLevelKernel(other),
            robot,
            one._J,  # type: ignore[arg-type]
            one._target,
            one._bias,
            one._w,
        )


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
def test_a_closed_loop_with_one_call_equals_it_with_two_to_the_bit(env_id: str) -> None:
    """The default controller (hand observers on, the MPC every tenth step) in closed loop on
    two copies of the env, one with each path: the same actions, bit for bit, over 150 steps
    that take the QP's shortcut (where the one call also computes the torques)."""
    import gymnasium as gym

    import wip_gym  # noqa: F401
    from controllers.hierarchical import HierarchicalConfig, HierarchicalController

    runs = []
    for one_call in (True, False):
        env = gym.make(env_id)
        obs, info = env.reset(seed=4)
        config = HierarchicalConfig(qp=QPSettings(one_call=one_call))
        policy = HierarchicalController.for_env(env, config)
        policy.reset(obs, info)
        runs.append((env, policy, obs))
    (env_a, policy_a, obs_a), (env_b, policy_b, obs_b) = runs
    calls = policy_a.qp.proxqp_calls
    for _ in range(150):
        action_a, action_b = policy_a(obs_a), policy_b(obs_b)
        np.testing.assert_array_equal(action_a, action_b)
        obs_a, *_ = env_a.step(action_a)
        obs_b, *_ = env_b.step(action_b)
    assert policy_a.qp.proxqp_calls == calls  # every step by the shortcut
    assert policy_a.qp._table is not None and policy_b.qp._table is None
    env_a.close()
    env_b.close()


def test_the_heading_before_any_update_is_the_identity() -> None:
    robot = RobotModel(_load("krang"))
    np.testing.assert_array_equal(robot.heading_rotation, np.eye(3))
    assert not robot.heading_rotation.flags.writeable
