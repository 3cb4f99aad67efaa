"""The exact ``Jdot nu`` of the tasks (``controllers.low_level.motion_probe``) against the central
finite difference it replaced, on states that turn, pitch and move every joint."""

from __future__ import annotations

from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from controllers.hierarchical import HierarchicalConfig, HierarchicalController
from tests.jdot_nu_fd import central_difference_jdot_nu


@pytest.mark.parametrize(
    ("env_id", "goal", "mode"),
    [
        ("wip_gym/PlanarTray-v0", 2.0, "level"),
        ("wip_gym/KrangTray-v0", (2.0, 1.0), "level"),
        ("wip_gym/KrangTray-v0", (2.0, 1.0), "specific_force"),
    ],
)
def test_exact_jdot_nu_equals_the_finite_difference(env_id: str, goal, mode: str) -> None:
    env = gym.make(env_id, goal=goal)
    obs, info = env.reset(seed=3)
    policy = HierarchicalController.for_env(env, HierarchicalConfig(tray_mode=mode))
    policy.high_level.reset = lambda *args: SimpleNamespace()
    policy.reset(obs, info)
    robot, qp = policy.robot, policy.qp
    rng = np.random.default_rng(0)
    q0 = robot.q.copy()
    n = robot.layout.n_min
    for _ in range(10):
        q = q0 + rng.uniform(-0.3, 0.3, n)
        nu = rng.uniform(-1.5, 1.5, n)  # psid up to 1.5 rad/s in 3-D
        qpos, qvel = robot.full_state(q, nu, rng.uniform(-1, 1, 2))
        robot.update(qpos, qvel)
        exact = qp.jdot_nu(robot, policy.tasks)
        finite = central_difference_jdot_nu(robot, policy.tasks)
        assert np.abs(finite).max() > 0.05  # the states move: the drift is not trivially zero
        # the finite difference's own error (round-off over a 1e-6 step) is ~1e-9 here
        np.testing.assert_allclose(exact, finite, rtol=1e-6, atol=1e-7)
    env.close()
