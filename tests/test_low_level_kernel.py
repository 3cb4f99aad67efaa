"""The low level's one-call kernel (``controllers.low_level.kernel``) against the pieces it
fuses, computed here the plain way: eq. ``iso3`` by ``controllers.low_level.isolated_dynamics``,
the task rows by matrix products with ``E`` and ``e``, the QP by ``T^T T``, the constraints row by
row, the unconstrained minimiser by ``numpy.linalg.solve``; on random states of both robots."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_wbc import _limits, _load, _realistic_tasks, _set_state

from controllers.low_level.isolated_dynamics import isolated_dynamics
from controllers.low_level.kernel import LowLevelKernel
from controllers.low_level.task_qp import QPSettings, TaskQP
from wip_gym.robot_model import RobotModel
from wip_gym.small_linalg import (
    gram_into,
    matmul_into,
    matvec_into,
    matvec_transposed_into,
    row_dot,
)


def _close(actual: np.ndarray, expected: np.ndarray, tol: float = 1e-12) -> None:
    scale = max(1.0, float(np.abs(expected).max())) if expected.size else 1.0
    np.testing.assert_allclose(actual, expected, rtol=0.0, atol=tol * scale)


@pytest.mark.parametrize("name", ["krang", "planar7"])
def test_kernel_equals_the_plain_computation(name: str) -> None:
    robot = RobotModel(_load(name))
    low, high = _limits(robot)
    settings = QPSettings()
    qp = TaskQP(robot, low, high, settings)
    feasible_seen = {True: 0, False: 0}
    for seed in range(8):
        _set_state(robot, 700 + seed, still=seed % 2 == 0)
        tasks = _realistic_tasks(robot)
        H, g, C, lower, upper = qp.assemble(robot, None, tasks)  # iso3 inside the kernel
        kernel = qp.kernel
        iso = isolated_dynamics(robot)
        for ours, plain in (
            (kernel.calA, iso.calA),
            (kernel.Ph, iso.Ph),
            (kernel.E, iso.E),
            (kernel.e, iso.e),
        ):
            _close(ours, plain)
        J = np.vstack([task.jacobian(robot) for task in tasks])
        target = np.concatenate([task.reference_acceleration(robot) for task in tasks])
        w = np.concatenate([task.weights() for task in tasks])
        jdot_nu = qp.jdot_nu(robot, tasks)
        T = w[:, None] * (J @ iso.E)
        b = w * (target - jdot_nu - J @ iso.e)
        _close(H, T.T @ T + settings.regularization * np.eye(len(T.T)))
        _close(g, -T.T @ b)
        M = qp.M_act
        m = len(M)
        _close(C[:m], M @ iso.calA)
        _close(lower[:m], low - M @ iso.Ph)
        _close(upper[:m], high - M @ iso.Ph)
        h = settings.limit_horizon
        for row, column in enumerate(np.argmax(C[m:], axis=1)):
            index = column + 1  # x is not a QP variable
            drift = robot.q[index] + robot.nu[index] * h
            limits = robot.model.jnt_range[
                robot.model.dof_jntid[robot.layout.body_dof[index - robot.layout.index_q1 - 1]]
            ]
            _close(lower[m + row], 2.0 * (limits[0] - drift) / h**2)
            _close(upper[m + row], 2.0 * (limits[1] - drift) / h**2)
        x = np.linalg.solve(H, -g)
        _close(kernel.x, x, 1e-9)
        feasible = bool(np.all(C @ x >= lower) and np.all(C @ x <= upper))
        assert qp._feasible == feasible
        feasible_seen[feasible] += 1
        # the same with the caller's iso3
        H2, g2, *_ = qp.assemble(robot, iso, tasks)
        _close(H2, T.T @ T + settings.regularization * np.eye(len(T.T)))
        _close(g2, -T.T @ b)
    assert feasible_seen[True] > 0


def test_zero_skipping_products_equal_numpy() -> None:
    """The kernel's products (``wip_gym.small_linalg``: loops that skip zero entries, into the
    caller's buffer) against NumPy on operands like KrangTray-v0's: a task matrix whose last
    rows have one entry each (posture rows), an actuator map of one or two entries per row
    (made non-square here, to catch swapped bounds). The buffers start as garbage (every
    entry is written), an output may be a view of a larger buffer (written alone), and a NaN
    in ``T`` reaches the diagonal of ``T^T T``."""
    rng = np.random.default_rng(11)
    T = rng.normal(size=(30, 18))
    T[:14] *= rng.random((14, 18)) < 0.6
    T[14:] = 0.0
    T[np.arange(14, 30), rng.integers(0, 18, 16)] = rng.normal(size=16)
    M = np.zeros((20, 18))
    M[np.arange(18), rng.permutation(18)] = rng.normal(size=18)
    M[18, 3] = M[19, 5] = M[0, 1] = 0.5
    B, b, x = rng.normal(size=(18, 18)), rng.normal(size=30), rng.normal(size=18)
    H, C = np.full((18, 18), 7.0), np.full((24, 18), 7.0)
    gram_into(T, H)
    matmul_into(M, B, C[:20])
    _close(H, T.T @ T, 1e-14)
    _close(C[:20], M @ B, 1e-14)
    assert np.all(C[20:] == 7.0)
    v, u = np.full(20, 7.0), np.full(18, 7.0)
    matvec_into(M, x, v)
    matvec_transposed_into(T, b, u)
    _close(v, M @ x, 1e-14)
    _close(u, T.T @ b, 1e-14)
    assert row_dot(T, 3, x) == pytest.approx(T[3] @ x, abs=1e-13)
    T[20, np.flatnonzero(T[20])[0]] = np.nan
    gram_into(T, H)
    column = np.flatnonzero(np.isnan(T[20]))[0]
    assert np.isnan(H[column, column])


def test_a_nonfinite_row_is_never_feasible() -> None:
    """On a state whose unconstrained minimiser is feasible, a NaN target, or an inf in a
    one-entry (posture) row in the first QP variable's column (where the Cholesky
    factorisation of the zero-skipping ``T^T T`` goes through and leaves the minimiser NaN),
    makes the kernel answer "not feasible": the QP solver runs, never a nonfinite shortcut."""
    robot = RobotModel(_load("planar7"))
    low, high = _limits(robot)
    qp = TaskQP(robot, low, high, QPSettings())
    for seed in range(20):
        _set_state(robot, 900 + seed, still=True)
        tasks = _realistic_tasks(robot)
        J = np.vstack([task.jacobian(robot) for task in tasks])
        target = np.concatenate([task.reference_acceleration(robot) for task in tasks])
        w = np.concatenate([task.weights() for task in tasks])
        jdot_nu = qp.jdot_nu(robot, tasks)
        qp.assemble(robot, None, tasks)
        if qp.kernel.run(robot.A, robot.h, J, target, jdot_nu, w, robot.q, robot.nu):
            break
    else:
        pytest.fail("no feasible state among the seeds")
    kernel = qp.kernel

    def run(J: np.ndarray, target: np.ndarray) -> bool:
        return kernel.run(robot.A, robot.h, J, target, jdot_nu, w, robot.q, robot.nu)

    assert np.all(np.isfinite(kernel.x))
    bad = target.copy()
    bad[0] = np.nan
    assert not run(J, bad)
    posture = int(np.flatnonzero((J != 0).sum(axis=1) == 1)[-1])
    J_inf = J.copy()
    J_inf[posture] = 0.0
    J_inf[posture, 1] = np.inf  # T's column 0 (x is not a QP variable)
    assert not run(J_inf, target)
    assert run(J, target)  # the same state again: feasible
    # a QP variable no actuator reaches would keep a nonfinite calA row out of the constraint
    # rows (their product skips zero entries): refused when the kernel is made
    unreached = kernel.layout.actuator_map.copy()
    unreached[:, 2] = 0.0
    with pytest.raises(ValueError, match="reach an actuator"):
        LowLevelKernel(dataclasses.replace(kernel.layout, actuator_map=unreached))


def test_a_task_without_an_exact_jdot_nu_is_an_error() -> None:
    robot = RobotModel(_load("planar7"))
    _set_state(robot, 3)
    tasks = _realistic_tasks(robot)

    class NoDrift:
        name = "no_drift"

        def __init__(self, task: object) -> None:
            self._task = task

        def jacobian(self, robot: RobotModel) -> np.ndarray:
            return self._task.jacobian(robot)  # type: ignore[attr-defined]

        def reference_acceleration(self, robot: RobotModel) -> np.ndarray:
            return self._task.reference_acceleration(robot)  # type: ignore[attr-defined]

        def weights(self) -> np.ndarray:
            return self._task.weights()  # type: ignore[attr-defined]

    qp = TaskQP(robot, *_limits(robot), QPSettings())
    with pytest.raises(ValueError, match="no_drift"):
        qp.solve(robot, None, [*tasks, NoDrift(tasks[0])])


def test_a_layout_or_input_of_the_wrong_size_is_refused() -> None:
    """The compiled step reads the layout's arrays and ``run``'s inputs without bounds checks
    (two torque limits for eighteen actuators gave the third a bound from memory past the
    array): a kernel is not made on a layout of the wrong sizes, the controller's QP refuses
    torque limits of another length when they are assigned between steps, and ``run``
    refuses rows of another shape."""
    robot = RobotModel(_load("krang"))
    low, high = _limits(robot)
    qp = TaskQP(robot, low, high, QPSettings())
    _set_state(robot, 4)
    tasks = _realistic_tasks(robot)
    qp.solve(robot, None, tasks)
    layout = qp.kernel.layout
    n = layout.n_min - 1
    bad_layouts = {
        "torque_low": dataclasses.replace(layout, torque_low=layout.torque_low[:2]),
        "torque_high": dataclasses.replace(layout, torque_high=np.append(layout.torque_high, 1)),
        "index_q1": dataclasses.replace(layout, index_q1=n),
        "limit_indices": dataclasses.replace(layout, limit_indices=layout.limit_indices + 40),
        "actuator map": dataclasses.replace(layout, actuator_map=layout.actuator_map[:, 1:]),
    }
    for what, bad in bad_layouts.items():
        with pytest.raises(ValueError, match=what):
            LowLevelKernel(bad)
    qp.torque_low = low[:2]
    with pytest.raises(ValueError, match="torque_low must hold one limit per actuator"):
        qp.solve(robot, None, tasks)
    qp.torque_low = low
    qp.solve(robot, None, tasks)
    J, target, w = qp.kernel.J, qp.kernel.target, qp.kernel.w
    jdot_nu = np.zeros_like(target)
    kernel = qp.kernel
    with pytest.raises(ValueError, match="J must be"):
        kernel.run(robot.A, robot.h, J[:5], target, jdot_nu, w, robot.q, robot.nu)
    with pytest.raises(ValueError, match="w must be"):
        kernel.run(robot.A, robot.h, J, target, jdot_nu, w[:-1], robot.q, robot.nu)
    with pytest.raises(ValueError, match="A and h must be"):
        kernel.run(robot.A[:-1], robot.h, J, target, jdot_nu, w, robot.q, robot.nu)
