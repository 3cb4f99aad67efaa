"""Every registered controller on the readable path (``wip_gym.mujoco_c.set_fast_path(False)``:
MuJoCo through its Python bindings, the task QP's readable reference) against the same
controller on the fast path, fed the same observations of a closed loop: the same actions, to
the bit where the arithmetic is the same (the robot model's readable update equals the fast
one to the bit, so a controller without a task QP acts alike), to 1e-9 of their scale with the
task QP (its readable rows differ from the compiled ones in the last bits). The env's two paths
are held equal by ``tests/test_env_step_reference.py``."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from controllers.low_level.task_stack import supports
from controllers.registry import default_controller_names, make_policy
from wip_gym import mujoco_c

STEPS = 150


def _readable_policy(name: str, env: gym.Env[Any, Any]) -> Any:
    mujoco_c.set_fast_path(False)
    try:
        return make_policy(name, env)
    finally:
        mujoco_c.set_fast_path(None)


@pytest.mark.parametrize("env_id", ["wip_gym/PlanarTray-v0", "wip_gym/KrangTray-v0"])
@pytest.mark.parametrize("name", default_controller_names())
def test_a_controller_on_the_readable_path_acts_as_on_the_fast_one(env_id: str, name: str) -> None:
    env = gym.make(env_id)
    obs, info = env.reset(seed=6)
    fast, readable = make_policy(name, env), _readable_policy(name, env)
    assert fast.robot.fast_path and not readable.robot.fast_path
    for policy in (fast, readable):
        policy.reset(obs, info)
    has_qp = hasattr(fast, "qp")
    for step in range(STEPS):
        action, other = fast(obs), readable(obs)
        if has_qp:
            scale = max(1.0, float(np.abs(action).max()))
            np.testing.assert_allclose(other, action, rtol=0, atol=1e-9 * scale, err_msg=str(step))
        else:
            np.testing.assert_array_equal(other, action, err_msg=str(step))
        obs, _, terminated, _, _ = env.step(action)
        assert not terminated
    if has_qp:
        # every row compiled on the fast path (a tray on two hands too: its hand pair has
        # compiled rows), none on the readable one
        tasks = getattr(fast, "_qp_tasks", fast.tasks)
        constraints = getattr(fast, "_qp_constraints", fast.constraints)
        assert supports(tasks, constraints, fast.robot.layout.planar)
        assert fast.qp.compiled and not readable.qp.compiled
    for policy in (fast, readable):
        getattr(getattr(policy, "high_level", None), "close", lambda: None)()
    env.close()
