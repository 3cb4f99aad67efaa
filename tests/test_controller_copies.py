"""Every default controller (``default_controller_names``) copied or pickled mid-episode (its
plan made, its MPC and QP run) goes on as the original: on the same observations, the same
actions to the bit (while no step goes to ProxQP, whose solver a copy starts anew)."""

from __future__ import annotations

import copy
import pickle
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from controllers.registry import default_controller_names, make_policy

COPIERS: dict[str, Callable[[Any], Any]] = {
    "deepcopy": copy.deepcopy,
    "pickle": lambda policy: pickle.loads(pickle.dumps(policy)),
}


@pytest.mark.parametrize("copier", sorted(COPIERS))
@pytest.mark.parametrize("name", default_controller_names())
def test_a_controller_copied_mid_episode_goes_on_as_the_original(name: str, copier: str) -> None:
    env = gym.make("wip_gym/PlanarTray-v0")
    obs, info = env.reset(seed=2)
    policy = make_policy(name, env)
    policy.reset(obs, info)
    for _ in range(15):  # past an MPC step
        obs, *_ = env.step(policy(obs))
    twin = COPIERS[copier](policy)
    qp = getattr(policy, "qp", None)
    calls = None if qp is None else qp.proxqp_calls
    for k in range(25):
        action = policy(obs)
        np.testing.assert_array_equal(twin(obs), action, err_msg=f"{name}, step {k}")
        obs, *_ = env.step(action)
    # equal to the bit while no step goes to ProxQP: a copy's ProxQP starts cold, and agrees
    # with the original's to ProxQP's tolerance only (tests/test_compiled_step.py)
    assert qp is None or qp.proxqp_calls == calls
    env.close()
