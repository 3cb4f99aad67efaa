"""The MPC run beside the control loop (``HighLevelConfig.mpc_delay_steps``): the solve from
step ``k``'s state is used from step ``k + d`` on, whatever the machine's speed."""

from __future__ import annotations

import dataclasses
import pickle

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from controllers.hierarchical import HierarchicalConfig, HierarchicalController
from controllers.high_level.receding_horizon import HighLevel, HighLevelConfig

STEPS = 45


def _run(delay: int) -> tuple[np.ndarray, list[int]]:
    env = gym.make("wip_gym/PlanarTray-v0", max_episode_steps=-1)
    obs, info = env.reset(seed=4)
    config = HierarchicalConfig(high_level=HighLevelConfig(mpc_delay_steps=delay))
    policy = HierarchicalController.for_env(env, config)
    policy.reset(obs, info)
    actions, starts = [], []
    for _ in range(STEPS):
        action = policy(obs)
        actions.append(action)
        starts.append(policy.high_level._last_start)
        obs, *_ = env.step(action)
    env.close()
    return np.array(actions), starts


def test_delayed_solutions_are_used_d_steps_after_their_state() -> None:
    delay = 4
    actions, starts = _run(delay)
    # the first solve is synchronous; every later one starts at a multiple of 10 steps and is
    # in use from d steps after it
    expected = [0 if k < 10 + delay else 10 * ((k - delay) // 10) for k in range(STEPS)]
    assert starts == expected
    again, _ = _run(delay)
    np.testing.assert_array_equal(actions, again)  # deterministic: threads do not leak timing
    synchronous, sync_starts = _run(0)
    assert sync_starts == [10 * (k // 10) for k in range(STEPS)]
    # the same until the first tick whose solve is delayed; then the older prediction
    np.testing.assert_array_equal(actions[:10], synchronous[:10])
    assert not np.allclose(actions[10:], synchronous[10:])


def test_delay_is_validated_and_the_high_level_pickles() -> None:
    with pytest.raises(ValueError, match="mpc_delay_steps"):
        HighLevel(HighLevelConfig(mpc_delay_steps=10), 1e-3)
    with pytest.raises(ValueError, match="mpc_delay_steps"):
        HighLevel(dataclasses.replace(HighLevelConfig(), mpc_delay_steps=-1), 1e-3)
    high_level = HighLevel(HighLevelConfig(mpc_delay_steps=3), 1e-3)
    high_level._executor = __import__("concurrent.futures").futures.ThreadPoolExecutor(1)
    copy = pickle.loads(pickle.dumps(high_level))
    assert copy._executor is None and copy.config.mpc_delay_steps == 3
