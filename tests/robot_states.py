"""States the low level's row tests read: a robot model at an env's reset, and random states
about it on and off the rolling manifold (shared by tests/test_object_balance.py,
tests/test_object_tasks.py and tests/test_hand_pair.py)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import gymnasium as gym
import numpy as np

import wip_gym  # noqa: F401
from wip_gym.robot_model import RobotModel


def robot_at_reset(env_id: str, seed: int = 0) -> tuple[gym.Env[Any, Any], RobotModel]:
    """The env reset with ``seed`` and a robot model on its MuJoCo model, at its state."""
    env = gym.make(env_id)
    env.reset(seed=seed)
    robot = RobotModel(env.unwrapped.model)
    data = env.unwrapped.data
    robot.update(data.qpos[: robot.layout.nq], data.qvel[: robot.layout.nv])
    return env, robot


def random_states(
    robot: RobotModel, rng: np.random.Generator, count: int
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """``count`` states ``(qpos, qvel)`` about the robot's current one: every joint and the lean
    moved by up to 0.3, every rate by up to 1, the place by up to 1 m; every second one off the
    rolling manifold, as the closed loop's measured states are."""
    lay = robot.layout
    q0, nu0 = robot.q.copy(), robot.nu.copy()
    for step in range(count):
        q = q0 + rng.uniform(-0.3, 0.3, lay.n_min)
        nu = nu0 + rng.uniform(-1.0, 1.0, lay.n_min)
        qpos, qvel = robot.full_state(q, nu, rng.uniform(-1, 1, 2))
        if step % 2:
            qpos = qpos + 1e-5 * rng.normal(size=qpos.shape)
            qvel = qvel + 2e-3 * rng.normal(size=qvel.shape)
            if not lay.planar:
                qpos[3:7] /= np.linalg.norm(qpos[3:7])
        yield qpos, qvel
