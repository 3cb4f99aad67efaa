"""Extending the task QP without editing it: extra constraint rows
(``controllers.low_level.constraints``) on both of its paths, the public frame and body point
API (``body_point_in_axle_frame``, ``MotionProbe.body_point_motion``), and a user's own task
and constraint added to the hierarchical controller through its config."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from test_wbc import _limits, _load, _realistic_tasks, _set_state

import wip_gym  # noqa: F401
from controllers.hierarchical import HierarchicalConfig, HierarchicalController
from controllers.low_level.constraints import AccelerationBound
from controllers.low_level.motion_probe import MotionProbe
from controllers.low_level.task_qp import QPSettings, TaskQP
from controllers.low_level.tasks import PDTask, body_point_in_axle_frame, site_in_axle_frame
from tests.jdot_nu_fd import central_difference_jdot_nu
from wip_gym.robot_model import RobotModel

Array = np.ndarray


@pytest.mark.parametrize("name", ["krang", "planar7"])
def test_an_acceleration_bound_holds_on_both_paths(name: str) -> None:
    """A bound on one joint's acceleration, tighter than what the tasks ask for, is met by the
    QP's solution on the compiled path and on the readable one (which agree), through ProxQP;
    a loose one leaves the unconstrained shortcut and its solution as without it, to the bit."""
    robot = RobotModel(_load(name))
    low, high = _limits(robot)
    paths = [TaskQP(robot, low, high, QPSettings(compiled_tasks=on)) for on in (True, False)]
    for seed in range(3):
        _set_state(robot, 40 + seed, still=True)
        tasks = _realistic_tasks(robot)
        free = [qp.solve(robot, None, tasks) for qp in paths]
        free = [qp.solve(robot, None, tasks) for qp in paths]  # ProxQP warm: the shortcut
        assert all(solution.iterations == 0 for solution in free)
        column = int(np.argmax(np.abs(free[0].nu_dot[robot.layout.index_q1 + 1 :])))
        column += robot.layout.index_q1 + 1
        wanted = free[0].nu_dot[column]
        bound = AccelerationBound(np.array([column]), -0.5 * abs(wanted), 0.5 * abs(wanted))
        solutions = [qp.solve(robot, None, tasks, [bound]) for qp in paths]
        assert paths[0].compiled and not paths[1].compiled
        for solution in solutions:
            assert solution.solved and solution.iterations > 0  # the shortcut would break it
            value = solution.nu_dot[column]
            assert -0.5 * abs(wanted) - 1e-6 <= value <= 0.5 * abs(wanted) + 1e-6
            assert abs(abs(value) - 0.5 * abs(wanted)) < 1e-6  # active
        scale = max(1.0, float(np.abs(solutions[1].actuators).max()))
        np.testing.assert_allclose(
            solutions[0].actuators, solutions[1].actuators, rtol=0, atol=1e-6 * scale
        )
        # the kernel's extra row is the joint's row of nu_dot = E qdd + e
        kernel = paths[0].kernel
        assert kernel is not None
        np.testing.assert_array_equal(kernel.C[-1], kernel.E[column])
        loose = AccelerationBound(np.array([column]), -1e6, 1e6)
        for qp, without in zip(paths, free, strict=True):
            again = qp.solve(robot, None, tasks, [loose])
            assert again.iterations == 0
            np.testing.assert_array_equal(again.actuators, without.actuators)


def test_a_constraint_needs_bounds_per_column() -> None:
    robot = RobotModel(_load("planar7"))
    _set_state(robot, 3)
    qp = TaskQP(robot, *_limits(robot), QPSettings())
    bound = AccelerationBound(np.array([3, 4]), [-1.0, -2.0, -3.0], 1.0)
    with pytest.raises(ValueError, match="acceleration_bound.*lower bounds"):
        qp.solve(robot, None, _realistic_tasks(robot), [bound])


@dataclass
class PointHeightTask(PDTask):
    """A user's task, written outside the package: hold the height of a point fixed on a body
    (``offset`` in the body's frame), in the axle frame."""

    body: int
    offset: Array
    target: float
    weight: float = 5.0
    kp: float = 100.0
    kv: float = 20.0
    name: str = "point_height"

    def jacobian(self, robot: RobotModel) -> Array:
        return body_point_in_axle_frame(robot, self.body, self.offset)[2][2:]

    def error(self, robot: RobotModel) -> Array:
        return body_point_in_axle_frame(robot, self.body, self.offset)[0][2:] - self.target

    def rate_error(self, robot: RobotModel) -> Array:
        return self.jacobian(robot) @ robot.nu

    def weights(self) -> Array:
        return np.array([self.weight])

    def jdot_nu(self, probe: MotionProbe) -> Array:
        position, velocity, drift, _, _ = probe.body_point_motion(self.body, self.offset)
        return np.array([probe.relative_drift(position, velocity, drift)[2][2]])


def test_a_body_point_is_a_site_where_one_is() -> None:
    """A body point placed where a site is has the site's position and Jacobians, and its
    drift is the site's; its ``Jdot nu`` is the finite difference's."""
    robot = RobotModel(_load("krang"))
    _set_state(robot, 8)
    m, d = robot.model, robot.data
    site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "ee")
    body = int(m.site_bodyid[site])
    offset = d.xmat[body].reshape(3, 3).T @ (d.site_xpos[site] - d.xpos[body])
    ours, theirs = body_point_in_axle_frame(robot, body, offset), site_in_axle_frame(robot, site)
    for a, b in zip(ours[::2], theirs[::2], strict=True):  # position and Jp (rotations differ)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ours[3], theirs[3], rtol=0, atol=1e-12)  # Jr: the same body
    probe = MotionProbe(robot)
    probe.update(robot)
    for a, b in zip(probe.body_point_motion(body, offset), probe.site_motion(site), strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
    task = PointHeightTask(body, offset, 1.0)
    np.testing.assert_allclose(
        task.jdot_nu(probe), central_difference_jdot_nu(robot, [task]), rtol=0, atol=1e-6
    )
    with pytest.raises(ValueError, match="3-vector offset"):
        body_point_in_axle_frame(robot, body, (0.0, 1.0))


def _tray_point(robot: RobotModel) -> Any:
    """The factory of a point-height task on the hand's body, 5 cm above its origin, held 2 cm
    above its height at reset."""
    m = robot.model
    body = int(m.site_bodyid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "ee")])
    offset = np.array([0.0, 0.0, 0.05])
    height = body_point_in_axle_frame(robot, body, offset)[0][2]
    return PointHeightTask(body, offset, float(height) + 0.02, weight=50.0)


def test_a_users_body_point_task_and_constraint_run_in_the_controller() -> None:
    """The config's extra tasks and constraints reach the controller's QP at reset, without
    editing it: the user's task (readable path: its class has no compiled rows) raises the
    hand's point toward its target while the robot balances, where the controller without it
    holds the point; a compiled constraint alone keeps the compiled path."""
    moved = {}
    for extra in ((), (_tray_point,)):
        env = gym.make("wip_gym/PlanarTray-v0")
        obs, info = env.reset(seed=2)
        policy = HierarchicalController.for_env(env, HierarchicalConfig(extra_tasks=extra))
        policy.reset(obs, info)
        task = _tray_point(policy.robot)  # the point, measured in both runs
        start = task.error(policy.robot)[0]
        for _ in range(200):
            obs, _, terminated, _, _ = env.step(policy(obs))
            assert not terminated
        policy.robot.update(obs["qpos"], obs["qvel"])
        moved[extra] = task.error(policy.robot)[0] - start
        assert len(policy.tasks) == 4 + len(extra)  # theta, hand (2, observed), posture
        assert policy.qp.compiled == (not extra)
        if extra:
            assert isinstance(policy.tasks[-1], PointHeightTask)
        policy.high_level.close()
        env.close()
    assert abs(moved[()]) < 5e-4 and moved[(_tray_point,)] > 2e-3  # raised toward +2 cm
    env = gym.make("wip_gym/PlanarTray-v0")
    obs, info = env.reset(seed=2)
    bounded = HierarchicalController.for_env(
        env,
        HierarchicalConfig(
            constraints=(lambda robot: AccelerationBound(np.array([2]), -50.0, 50.0),)
        ),
    )
    bounded.reset(obs, info)
    bounded(obs)
    assert bounded.qp.compiled and len(bounded.constraints) == 1
    bounded.high_level.close()
    env.close()


def test_the_config_refuses_what_is_no_factory() -> None:
    with pytest.raises(ValueError, match="extra_tasks must be a tuple of factories"):
        HierarchicalConfig(extra_tasks=(PointHeightTask(1, np.zeros(3), 0.0),))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="constraints must be a tuple"):
        HierarchicalConfig(constraints=[lambda robot: None])  # type: ignore[arg-type]
