"""The whole-body controller's low level: the isolated manipulator dynamics (eq. ``iso3``,
docs/ERRATA.md §4) and the task QP (``controllers.low_level.task_qp``), for ``planar7`` and
``krang``.

The isolated dynamics are checked against MuJoCo independently of ``RobotModel``'s ``A``,
``h``: the exact rolling-constrained dynamics by KKT (tests/dynamics_reference.py) and
``mj_inverse``. The reduced QP over ``qdd`` is checked against the full QP over
``[nu_dot, tau]`` with ``A nu_dot + h = B tau`` as equality constraints, built here.
"""

from __future__ import annotations

import sys
import types
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import proxsuite
import pytest
from dynamics_reference import constrained_accelerations, random_minimal_state
from numpy.typing import NDArray

from controllers.low_level.isolated_dynamics import isolated_dynamics
from controllers.low_level.task_qp import QPSettings, QPSolution, TaskQP, actuator_map
from controllers.low_level.tasks import (
    FrameOrientationTask,
    FramePositionTask,
    PDTask,
    PostureTask,
    SpinTask,
    Task,
    ThetaTask,
    site_in_axle_frame,
    site_velocity_in_axle_frame,
)
from wip_gym.assets import mjcf_path
from wip_gym.robot_model import RobotModel
from wip_gym.wheel_torques import wheel_to_generalized

Array = NDArray[np.float64]
ROBOTS = ["planar7", "krang"]
HUGE = 1e6


def _load(name: str) -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_path(str(mjcf_path(f"scene_{name}.xml")))


@pytest.fixture(scope="module", params=ROBOTS)
def robot(request: pytest.FixtureRequest) -> RobotModel:
    return RobotModel(_load(request.param))


def _referee_model(robot: RobotModel) -> mujoco.MjModel:
    """The robot's model without ctrl clamping and without constraints (contacts, joint
    limits): MuJoCo's bare rigid-body dynamics, for the referees."""
    model = _load("krang" if not robot.layout.planar else "planar7")
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CLAMPCTRL)
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    return model


def _limits(robot: RobotModel, fraction: float = 1.0) -> tuple[Array, Array]:
    ranges = robot.model.actuator_ctrlrange
    return fraction * ranges[:, 0].copy(), fraction * ranges[:, 1].copy()


def _set_state(robot: RobotModel, seed: int, *, still: bool = False) -> None:
    rng = np.random.default_rng(seed)
    q, nu = random_minimal_state(robot, rng)
    if still:
        nu[:] = 0.0
    robot.update(*robot.full_state(q, nu))


def _ee(robot: RobotModel) -> int:
    site = mujoco.mj_name2id(robot.model, mujoco.mjtObj.mjOBJ_SITE, "ee")
    assert site >= 0
    return int(site)


def _realistic_tasks(robot: RobotModel) -> list[Task]:
    """The hierarchical controller's task set (``HierarchicalController.reset``'s gains), the
    targets at (or a little off) the current values so that every task asks for something."""
    lay = robot.layout
    site = _ee(robot)
    position, rotation, _, _ = site_in_axle_frame(robot, site)
    tasks: list[Task] = [
        ThetaTask(100.0, 50.0, 100.0, theta_d=robot.theta + 0.02, thetad_d=0.0, thdd_d=0.5)
    ]
    if not lay.planar:
        tasks.append(SpinTask(10.0, 50.0, 20.0, psi_d=robot.psi + 0.05))
    tasks.append(
        FramePositionTask(site, position + np.array([0.01, 0.0, -0.01]), 10.0, 750.0, 250.0)
    )
    tasks.append(FrameOrientationTask(site, rotation.copy(), 10.0, 150.0, 50.0))
    columns = np.arange(lay.index_q1 + 1, lay.n_min)
    tasks.append(
        PostureTask(robot.q[columns].copy(), np.ones(len(columns)), 10.0, 20.0, columns=columns)
    )
    return tasks


def _jdot_nu(robot: RobotModel, tasks: Sequence[Task], eps: float = 1e-6) -> Array:
    """``Jdot nu`` of the stacked tasks by a central difference along ``q + t nu`` (own probe)."""
    probe = RobotModel(robot.model)
    q, nu = robot.q.copy(), robot.nu.copy()
    sides = []
    for sign in (1.0, -1.0):
        probe.update(*robot.full_state(q + sign * eps * nu, nu), dynamics=False)
        sides.append(np.concatenate([task.jacobian(probe) @ nu for task in tasks]))
    return (sides[0] - sides[1]) / (2 * eps)


def _limit_rows(robot: RobotModel, horizon: float) -> tuple[list[int], Array, Array]:
    """Minimal indices of the limited body joints and their acceleration bounds."""
    m, lay = robot.model, robot.layout
    indices, lo, hi = [], [], []
    for j, dof in enumerate(lay.body_dof):
        joint = m.dof_jntid[dof]
        if not m.jnt_limited[joint]:
            continue
        index = lay.index_q1 + 1 + j
        q_min, q_max = m.jnt_range[joint]
        q, qd = robot.q[index], robot.nu[index]
        indices.append(index)
        lo.append(2.0 * (q_min - q - qd * horizon) / horizon**2)
        hi.append(2.0 * (q_max - q - qd * horizon) / horizon**2)
    return indices, np.array(lo), np.array(hi)


# ------------------------------------------------------------------ isolated dynamics
def test_isolated_dynamics_give_the_torques_mujoco_needs(robot: RobotModel) -> None:
    """``calA qdd + P h``, mapped to the actuators, makes MuJoCo's exact rolling dynamics
    produce ``qdd`` (and ``xdd = E[x] qdd + e[x]``); ``mj_inverse`` agrees on the q rows."""
    model = _referee_model(robot)
    lay = robot.layout
    ix = lay.index_x
    M_act = actuator_map(robot)
    rng = np.random.default_rng(11)
    worst_forward = worst_inverse = worst_rolling = 0.0
    for _ in range(10):
        q, nu = random_minimal_state(robot, rng)
        qpos, qvel = robot.full_state(q, nu)
        robot.update(qpos, qvel)
        iso = isolated_dynamics(robot)
        assert iso.index_q1 == lay.index_q1 - 1
        assert iso.index_psi == (None if lay.planar else 0)
        np.testing.assert_array_equal(iso.q_indices, np.delete(np.arange(lay.n_min), ix))
        qdd = rng.normal(size=lay.n_min - 1) * 2.0
        gamma = iso.torques(qdd)
        np.testing.assert_allclose(gamma, iso.calA @ qdd + iso.Ph, rtol=1e-14, atol=0.0)
        ctrl = M_act @ gamma
        nu_dot = iso.E @ qdd + iso.e
        np.testing.assert_array_equal(nu_dot[iso.q_indices], qdd)

        # forward: MuJoCo's constrained dynamics by KKT, mapped back to minimal coordinates
        qacc = constrained_accelerations(model, qpos, qvel, ctrl, robot)
        nu_dot_mj = np.linalg.lstsq(robot.J_tf, qacc - robot.Jdot_tf_nu, rcond=None)[0]
        rolling = np.linalg.norm(robot.J_tf @ nu_dot_mj + robot.Jdot_tf_nu - qacc)
        worst_rolling = max(worst_rolling, rolling / np.linalg.norm(qacc))
        assert rolling <= 1e-9 * np.linalg.norm(qacc)
        error = np.linalg.norm(nu_dot_mj - nu_dot) / np.linalg.norm(nu_dot)
        worst_forward = max(worst_forward, error)
        assert error <= 1e-9, (error, nu_dot_mj - nu_dot)
        assert nu_dot_mj[ix] == pytest.approx(iso.E[ix] @ qdd + iso.e[ix], rel=1e-9, abs=1e-9)

        # inverse: the forces MuJoCo needs for that motion; the rolling constraint's share
        # vanishes under J_tf^T
        data = mujoco.MjData(model)
        data.qpos[:] = qpos
        data.qvel[:] = qvel
        data.qacc[:] = robot.J_tf @ nu_dot + robot.Jdot_tf_nu
        mujoco.mj_inverse(model, data)
        applied = np.zeros(model.nv)
        for a in range(model.nu):
            applied[model.jnt_dofadr[model.actuator_trnid[a, 0]]] += ctrl[a]
        constraint = data.qfrc_inverse - applied
        assert np.linalg.norm(constraint) > 1.0  # the wheels do need the ground's forces
        projected = robot.J_tf.T @ data.qfrc_inverse
        error = np.linalg.norm(projected - robot.J_tf.T @ applied) / np.linalg.norm(projected)
        worst_inverse = max(worst_inverse, error)
        assert error <= 1e-9, error
        np.testing.assert_allclose(robot.B @ ctrl, robot.J_tf.T @ applied, rtol=1e-12, atol=1e-9)
        # and the q rows of the projection are Gamma itself
        scale = np.linalg.norm(gamma)
        assert np.linalg.norm(projected[iso.q_indices] - gamma) <= 1e-9 * scale
    print(
        f"{'planar' if lay.planar else '3-D'}: forward {worst_forward:.1e}, "
        f"inverse {worst_inverse:.1e}, rolling {worst_rolling:.1e}"
    )


def test_actuator_map_inverts_the_actuation(robot: RobotModel) -> None:
    """``B (M_act Gamma)``: the q rows give Gamma back, the x row ``-tau_1 / R``."""
    lay = robot.layout
    _set_state(robot, 12)
    iso = isolated_dynamics(robot)
    M_act = actuator_map(robot)
    assert M_act.shape == (robot.model.nu, lay.n_min - 1)
    rng = np.random.default_rng(12)
    for _ in range(10):
        gamma = rng.normal(size=lay.n_min - 1) * 100.0
        ctrl = M_act @ gamma
        generalized = robot.B @ ctrl
        np.testing.assert_allclose(generalized[iso.q_indices], gamma, rtol=1e-12, atol=1e-10)
        tau_1 = gamma[iso.index_q1]
        assert generalized[lay.index_x] == pytest.approx(-tau_1 / lay.wheel_radius, rel=1e-12)
        assert generalized[lay.index_q1] == pytest.approx(tau_1, rel=1e-12)
        wl, wr = lay.wheel_actuators
        tau_0, tau_1_back = wheel_to_generalized(
            ctrl[wl], ctrl[wr], lay.wheel_radius, lay.wheel_separation
        )
        assert tau_1_back == pytest.approx(tau_1, rel=1e-12)
        if iso.index_psi is None:
            assert ctrl[wl] == pytest.approx(ctrl[wr], rel=1e-14)  # planar: an even split
        else:
            assert generalized[lay.index_psi] == pytest.approx(gamma[iso.index_psi], rel=1e-12)
            assert tau_0 == pytest.approx(gamma[iso.index_psi], rel=1e-12)
        for j, actuator in enumerate(lay.joint_actuators):
            assert ctrl[actuator] == gamma[iso.index_q1 + 1 + j]


# ----------------------------------------------------------------------- task QP
def _full_qp(
    robot: RobotModel,
    tasks: Sequence[Task],
    low: Array,
    high: Array,
    settings: QPSettings,
) -> tuple[Array, Array]:
    """The QP over ``[nu_dot, tau]`` with the whole ``A nu_dot + h = B tau`` as equalities,
    the same task cost (over ``nu_dot``), torque limits on ``tau`` and joint-limit rows."""
    lay, n, n_u = robot.layout, robot.layout.n_min, robot.model.nu
    J = np.vstack([task.jacobian(robot) for task in tasks])
    target = np.concatenate([task.reference_acceleration(robot) for task in tasks])
    w = np.concatenate([task.weights() for task in tasks])
    rows = w[:, None] * J
    rhs = w * (target - _jdot_nu(robot, tasks))
    H = np.zeros((n + n_u, n + n_u))
    g = np.zeros(n + n_u)
    H[:n, :n] = rows.T @ rows
    g[:n] = -rows.T @ rhs
    q_rows = np.delete(np.arange(n), lay.index_x)
    H[q_rows, q_rows] += settings.regularization
    if lay.planar:
        # tau_L - tau_R moves nothing on a planar robot: a tie-break toward an even split
        wl, wr = (n + a for a in lay.wheel_actuators)
        H[np.ix_([wl, wr], [wl, wr])] += np.array([[1.0, -1.0], [-1.0, 1.0]])
    A_eq = np.hstack([robot.A, -robot.B])
    b_eq = -robot.h
    indices, lo, hi = _limit_rows(robot, settings.limit_horizon)
    C = np.zeros((n_u + len(indices), n + n_u))
    C[:n_u, n:] = np.eye(n_u)
    C[n_u + np.arange(len(indices)), indices] = 1.0
    lower = np.concatenate([low, lo])
    upper = np.concatenate([high, hi])
    qp = proxsuite.proxqp.dense.QP(n + n_u, n, C.shape[0])
    qp.settings.eps_abs = 1e-10
    qp.settings.eps_rel = 0.0
    qp.settings.max_iter = 100000
    qp.init(H, g, A_eq, b_eq, C, lower, upper)
    qp.solve()
    assert qp.results.info.status == proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
    x = np.array(qp.results.x)
    return x[:n], x[n:]


@pytest.mark.parametrize("fraction", [1.0, 0.3])
def test_reduced_qp_equals_full_dynamics_qp(robot: RobotModel, fraction: float) -> None:
    """Eliminating ``xdd`` and ``tau`` (eq. ``iso3``) does not change the QP's solution."""
    settings = QPSettings()
    low, high = _limits(robot, fraction)
    worst_qdd = worst_tau = 0.0
    active_counts = []
    for seed in range(3):
        _set_state(robot, 100 + seed)
        tasks = _realistic_tasks(robot)
        iso = isolated_dynamics(robot)
        qp = TaskQP(robot, low, high, settings)
        solution = qp.solve(robot, iso, tasks)
        assert solution.solved
        nu_dot, tau = _full_qp(robot, tasks, low, high, settings)
        scale_qdd = max(np.abs(nu_dot).max(), 1.0)
        scale_tau = max(np.abs(tau).max(), 1.0)
        error_qdd = np.abs(solution.nu_dot - nu_dot).max() / scale_qdd
        error_tau = np.abs(solution.actuators - tau).max() / scale_tau
        worst_qdd, worst_tau = max(worst_qdd, error_qdd), max(worst_tau, error_tau)
        assert error_qdd <= 1e-6, (error_qdd, solution.nu_dot - nu_dot)
        assert error_tau <= 1e-6, (error_tau, solution.actuators - tau)
        active_counts.append(int(np.sum(np.minimum(tau - low, high - tau) < 1e-6)))
        # the reduced QP's torques satisfy the full dynamics
        residual = robot.A @ solution.nu_dot + robot.h - robot.B @ solution.actuators
        assert np.linalg.norm(residual) <= 1e-8 * max(np.linalg.norm(robot.h), 1.0)
        # and its task rows are the full QP's through nu_dot = E qdd + e
        T, b = qp.task_rows(robot, iso, tasks)
        J = np.vstack([task.jacobian(robot) for task in tasks])
        w = np.concatenate([task.weights() for task in tasks])
        np.testing.assert_allclose(T, w[:, None] * (J @ iso.E), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(qp.jdot_nu(robot, tasks), _jdot_nu(robot, tasks), atol=1e-9)
    if fraction < 1.0:
        assert max(active_counts) > 0, "the tight case should have an active torque limit"
    print(f"fraction {fraction}: qdd {worst_qdd:.1e}, tau {worst_tau:.1e}, active {active_counts}")


def _second_derivative(
    robot: RobotModel, nu_dot: Array, value: Callable[[RobotModel], Array], step: float = 1e-4
) -> Array:
    """``d^2/dt^2 value(q(t))`` at 0 along ``q(t) = q + nu t + nu_dot t^2 / 2``."""
    probe = RobotModel(robot.model)
    q, nu = robot.q.copy(), robot.nu.copy()
    values = []
    for t in (-step, 0.0, step):
        probe.update(
            *robot.full_state(q + nu * t + 0.5 * nu_dot * t**2, nu + nu_dot * t), dynamics=False
        )
        values.append(np.atleast_1d(value(probe)).copy())
    return (values[0] - 2.0 * values[1] + values[2]) / step**2


@pytest.mark.parametrize("theta_weight", [10.0, 100.0])
def test_one_task_with_loose_limits_gets_its_reference(
    robot: RobotModel, theta_weight: float
) -> None:
    """A lone task with loose limits is met exactly: ``J nu_dot + Jdot nu`` is the reference
    acceleration, and so is the second derivative of the task's value along the motion.
    ``theta_weight`` 10 is the authors', 100 ``HierarchicalConfig``'s."""
    low, high = np.full(robot.model.nu, -HUGE), np.full(robot.model.nu, HUGE)
    site = _ee(robot)
    _set_state(robot, 21)
    position = site_in_axle_frame(robot, site)[0]
    cases: list[tuple[Task, Callable[[RobotModel], Array]]] = [
        (
            ThetaTask(theta_weight, 50.0, 100.0, theta_d=robot.theta + 0.01, thdd_d=1.5),
            lambda r: np.array([r.theta]),
        ),
        (
            FramePositionTask(site, position + np.array([0.02, 0.0, 0.01]), 10.0, 750.0, 250.0),
            lambda r: site_in_axle_frame(r, site)[0],
        ),
    ]
    for task, value in cases:
        qp = TaskQP(robot, low, high, QPSettings())
        solution = qp.solve(robot, isolated_dynamics(robot), [task])
        assert solution.solved
        reference = task.reference_acceleration(robot)
        achieved = task.jacobian(robot) @ solution.nu_dot + _jdot_nu(robot, [task])
        error = np.abs(achieved - reference).max() / max(np.abs(reference).max(), 1.0)
        actual = _second_derivative(robot, solution.nu_dot, value)
        fd_error = np.abs(actual - reference).max() / max(np.abs(reference).max(), 1.0)
        print(
            f"{task.name}: |ref| {np.abs(reference).max():.2f}, error {error:.1e}, "
            f"finite-difference {fd_error:.1e}"
        )
        assert np.abs(reference).max() > 0.1
        assert error <= 1e-6, (achieved, reference)
        assert fd_error <= 1e-5, (actual, reference)


def _documented_task_class(monkeypatch: pytest.MonkeyPatch) -> Any:
    """``SiteHeightTask``, the task of a new kind that docs/extending.md §1 writes, from the docs
    themselves: the example is what the test runs."""
    text = (Path(__file__).parents[1] / "docs" / "extending.md").read_text()
    snippet = next(b for b in text.split("```python")[1:] if "class SiteHeightTask" in b)
    module = types.ModuleType("docs_extending")  # dataclass reads its class's module
    monkeypatch.setitem(sys.modules, module.__name__, module)
    exec(snippet.split("```")[0], module.__dict__)  # noqa: S102 (the repository's own docs)
    assert issubclass(module.SiteHeightTask, PDTask)
    return module.SiteHeightTask


def test_a_task_of_a_new_kind_gets_the_pd_law_and_its_reference(
    robot: RobotModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A task written on ``PDTask`` with only its kinematics (``SiteHeightTask``, as the docs
    write it) runs on the QP's Python path, beside a stock task too; its reference is the PD
    law on its error and rate error, and with loose limits the motion meets it: ``J nu_dot +
    Jdot nu`` exactly, and the height's second derivative along the motion by finite
    differences."""
    SiteHeightTask = _documented_task_class(monkeypatch)
    low, high = np.full(robot.model.nu, -HUGE), np.full(robot.model.nu, HUGE)
    site = _ee(robot)
    _set_state(robot, 22)
    height = float(site_in_axle_frame(robot, site)[0][2])
    # the docs' weight, 10, as the stock tasks': with weight 1 the QP's regularisation of qdd
    # (1e-6) would leave 2.6e-6 of the reference unmet
    task = SiteHeightTask(site, height - 0.02)
    assert task.weights().tolist() == [10.0]
    reference = task.reference_acceleration(robot)
    velocity = float(site_velocity_in_axle_frame(robot, site)[0][2])
    np.testing.assert_allclose(reference, [-100.0 * 0.02 - 20.0 * velocity], rtol=1e-12)
    assert abs(reference[0]) > 0.1
    qp = TaskQP(robot, low, high, QPSettings())
    solution = qp.solve(robot, isolated_dynamics(robot), [task])
    assert solution.solved and not qp.compiled  # a new kind: the Python path
    achieved = task.jacobian(robot) @ solution.nu_dot + _jdot_nu(robot, [task])
    assert np.abs(achieved - reference).max() <= 1e-6 * max(1.0, abs(reference[0]))
    actual = _second_derivative(
        robot, solution.nu_dot, lambda r: site_in_axle_frame(r, site)[0][2:3]
    )
    assert np.abs(actual - reference).max() <= 1e-5 * max(1.0, abs(reference[0]))
    # beside a stock task: both rows go in, by the Python path
    theta = ThetaTask(100.0, 50.0, 100.0, theta_d=robot.theta)
    both = TaskQP(robot, low, high, QPSettings()).solve(
        robot, isolated_dynamics(robot), [theta, task]
    )
    assert both.solved
    # a task that leaves out what it measures is told so by name
    with pytest.raises(NotImplementedError, match="PDTask must give error"):
        PDTask().reference_acceleration(robot)


def test_the_documented_compiled_rows_of_the_new_kind_equal_its_object(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """docs/extending.md §1's ``site_height_rows``, run on a step's table (a stock frame task on
    the same site gives it its site slot), fills the rows ``SiteHeightTask`` gives: the same
    Jacobian, reference, weight and ``Jdot nu``, to 1e-12 of their scale."""
    from numba import njit

    from controllers.low_level import compiled_tasks as ct
    from controllers.low_level.motion_probe import MotionProbe
    from wip_gym.array_table import float_cube, float_matrix, float_vector, int_vector

    SiteHeightTask = _documented_task_class(monkeypatch)
    text = (Path(__file__).parents[1] / "docs" / "extending.md").read_text()
    snippet = next(b for b in text.split("```python")[1:] if "def site_height_rows" in b)
    namespace = {
        "njit": njit, "ITEM": ct.ITEM, "S": ct.S, "_pd": ct._pd, "_point_motion": ct._point_motion,
        "_relative_drift": ct._relative_drift, "float_cube": float_cube,
        "float_matrix": float_matrix, "float_vector": float_vector, "int_vector": int_vector,
    }  # fmt: skip
    # the package's functions are cached on disk; the docs' copy is compiled in memory
    exec(snippet.split("```")[0].replace("cache=True", "cache=False"), namespace)  # noqa: S102
    robot = RobotModel(_load("krang"))
    _set_state(robot, 23)
    low, high = _limits(robot)
    qp = TaskQP(robot, low, high, QPSettings())
    tasks = _realistic_tasks(robot)
    qp.assemble(robot, None, tasks)
    stack = qp._stack
    assert stack is not None
    k = next(k for k, task in enumerate(tasks) if isinstance(task, FramePositionTask))
    task = SiteHeightTask(
        tasks[k].site, float(site_in_axle_frame(robot, tasks[k].site)[0][2]) - 0.02
    )
    rows = np.zeros((1, robot.layout.n_min)), np.zeros(1), np.zeros(1), np.zeros(1)
    parameters = np.array([task.kp, task.kv, task.height, task.weight])
    namespace["site_height_rows"](stack.table.rows, stack.items[k], parameters, *rows)
    probe = MotionProbe(robot)
    probe.update(robot)
    expected = (
        task.jacobian(robot),
        task.reference_acceleration(robot),
        task.jdot_nu(probe),
        task.weights(),
    )
    for ours, theirs in zip(rows, expected, strict=True):
        scale = max(1.0, float(np.abs(theirs).max()))
        np.testing.assert_allclose(ours, theirs, rtol=0.0, atol=1e-12 * scale)
    assert abs(expected[1][0]) > 0.1 and abs(expected[2][0]) > 1e-6  # something to compare


def test_tight_torque_limits_hold(robot: RobotModel) -> None:
    """At 5 % of the real limits the unconstrained answer breaks them; the QP's does not."""
    settings = QPSettings()
    low, high = _limits(robot, 0.05)
    for seed in range(3):
        _set_state(robot, 200 + seed, still=True)
        tasks = _realistic_tasks(robot)
        iso = isolated_dynamics(robot)
        free = TaskQP(robot, np.full_like(low, -HUGE), np.full_like(high, HUGE), settings)
        loose = free.solve(robot, iso, tasks)
        assert loose.solved
        assert np.any((loose.actuators < low) | (loose.actuators > high))
        qp = TaskQP(robot, low, high, settings)
        solution = qp.solve(robot, iso, tasks)
        assert solution.solved
        tau = solution.actuators
        assert np.all(tau >= low - 1e-6) and np.all(tau <= high + 1e-6), (tau, low, high)
        slack = np.minimum(tau - low, high - tau)
        assert np.sum(slack < 1e-6) > 0
        print(
            f"seed {seed}: {int(np.sum(slack < 1e-6))} of {len(tau)} limits active, "
            f"worst violation {max(0.0, -slack.min()):.1e}"
        )
        np.testing.assert_allclose(tau, actuator_map(robot) @ iso.torques(solution.qdd))


def test_wheel_limits_bound_the_wheels_not_tau01() -> None:
    """A demand whose ``(tau_0, tau_1)`` lies inside the boxes ``|tau_0| <= sep/r w``,
    ``|tau_1| <= 2 w`` (the images of ``|tau_L|, |tau_R| <= w``) while a wheel exceeds ``w``:
    the QP keeps both wheels within ``w``."""
    robot = RobotModel(_load("krang"))
    lay = robot.layout
    r, sep = lay.wheel_radius, lay.wheel_separation
    wl, wr = lay.wheel_actuators
    settings = QPSettings()
    _set_state(robot, 300, still=True)
    columns = np.arange(lay.index_q1 + 1, lay.n_min)
    tasks: list[Task] = [
        ThetaTask(100.0, 50.0, 100.0, theta_d=robot.theta + 0.05),
        SpinTask(10.0, 50.0, 20.0, psi_d=robot.psi, psidd_d=8.0),
        PostureTask(robot.q[columns].copy(), np.ones(len(columns)), 10.0, 20.0, columns=columns),
    ]
    iso = isolated_dynamics(robot)
    free = TaskQP(robot, np.full(robot.model.nu, -HUGE), np.full(robot.model.nu, HUGE), settings)
    loose = free.solve(robot, iso, tasks)
    tau_0, tau_1 = loose.generalized[iso.index_psi], loose.generalized[iso.index_q1]
    a, b = r / sep * abs(tau_0), 0.5 * abs(tau_1)
    assert min(a, b) > 0.1 * max(a, b), (tau_0, tau_1)  # both ask for something
    w = 0.5 * (max(a, b) + a + b)  # max(a, b) < w < a + b = max(|tau_L|, |tau_R|)
    assert abs(tau_0) < sep / r * w and abs(tau_1) < 2.0 * w
    assert max(abs(loose.actuators[wl]), abs(loose.actuators[wr])) > w
    low, high = np.full(robot.model.nu, -HUGE), np.full(robot.model.nu, HUGE)
    low[[wl, wr]], high[[wl, wr]] = -w, w
    solution = TaskQP(robot, low, high, settings).solve(robot, iso, tasks)
    assert solution.solved
    wheels = solution.actuators[[wl, wr]]
    print(f"unconstrained wheels {loose.actuators[[wl, wr]]}, w {w:.2f}, QP wheels {wheels}")
    assert np.all(np.abs(wheels) <= w + 1e-6), wheels
    assert np.max(np.abs(wheels)) >= w - 1e-6


# ---------------------------------------------------------------- status checking
@pytest.fixture
def capped_proxqp(monkeypatch: pytest.MonkeyPatch) -> None:
    """ProxQP objects limited to 100 outer iterations: with the defaults (10 000 outer, 1 500
    inner) an infeasible QP here runs for about a minute before giving up."""
    real = proxsuite.proxqp.dense.QP

    def capped(n: int, n_eq: int, n_in: int) -> proxsuite.proxqp.dense.QP:
        qp = real(n, n_eq, n_in)
        qp.settings.max_iter = 100
        return qp

    monkeypatch.setattr(proxsuite.proxqp.dense, "QP", capped)


@pytest.mark.usefixtures("capped_proxqp")
def test_unsolved_qp_falls_back_to_the_last_feasible_torques() -> None:
    """Contradicting limits (planar: both wheels carry ``-tau_1 / 2``, so ``tau_L = 10`` and
    ``tau_R = -10`` cannot both hold): the QP reports failure, counts it, and returns the last
    feasible torques; a feasible QP afterwards is solved again."""
    robot = RobotModel(_load("planar7"))
    lay = robot.layout
    wl, wr = lay.wheel_actuators
    settings = QPSettings()
    _set_state(robot, 400, still=True)
    tasks = _realistic_tasks(robot)
    iso = isolated_dynamics(robot)
    low, high = _limits(robot)
    qp = TaskQP(robot, low, high, settings)
    first = qp.solve(robot, iso, tasks)
    assert first.solved and qp.failures == 0
    contradicting_low, contradicting_high = low.copy(), high.copy()
    contradicting_low[wl] = contradicting_high[wl] = 10.0
    contradicting_low[wr] = contradicting_high[wr] = -10.0
    qp.torque_low, qp.torque_high = contradicting_low, contradicting_high
    for count in (1, 2):
        failed: QPSolution = qp.solve(robot, iso, tasks)
        assert not failed.solved
        assert qp.failures == count
        np.testing.assert_array_equal(failed.actuators, first.actuators)
        assert np.all(np.isnan(failed.qdd)) and np.all(np.isnan(failed.nu_dot))
    qp.torque_low, qp.torque_high = low, high
    again = qp.solve(robot, iso, tasks)
    assert again.solved and qp.failures == 2
    np.testing.assert_allclose(again.actuators, first.actuators, rtol=1e-6, atol=1e-6)


@pytest.mark.usefixtures("capped_proxqp")
def test_first_qp_unsolved_raises(monkeypatch: pytest.MonkeyPatch) -> None:
    """With no feasible torques yet there is nothing to fall back to."""
    robot = RobotModel(_load("planar7"))
    _set_state(robot, 401, still=True)
    iso = isolated_dynamics(robot)
    qp = TaskQP(robot, *_limits(robot), QPSettings())
    original = qp.assemble

    def contradicting(*args: object) -> tuple[Array, Array, Array, Array, Array]:
        H, g, C, lower, upper = original(*args)
        C = C.copy()
        C[1] = C[0]  # the same row twice, with disjoint bounds
        lower, upper = lower.copy(), upper.copy()
        lower[0], upper[0] = 1.0, 1.0
        lower[1], upper[1] = 2.0, 2.0
        return H, g, C, lower, upper

    monkeypatch.setattr(qp, "assemble", contradicting)
    with pytest.raises(RuntimeError, match="first task QP"):
        qp.solve(robot, iso, _realistic_tasks(robot))
    assert qp.failures == 1
