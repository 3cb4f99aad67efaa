"""Controllers see only the observation (docs/realism.md §8): every registered controller's
torques are a function of the observations it was given and of what ``for_env`` read at
construction (the nominal model, the declared task), nothing of the env's simulator; they
change under sensor noise; and with every perturbation argument at its off value they are
today's to the bit."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from controllers.registry import controller_names, default_controller_names, make_policy
from tests.test_perturbations import OFF

STEPS = 40
ENVS = ("wip_gym/PlanarTray-v0", "wip_gym/Krang-v0")


def _make(env_id: str, **kwargs: Any) -> Any:
    return gym.make(env_id, max_episode_steps=100_000, **kwargs)


def _episode(env: Any, policy: Any, seed: int, shadow: Any = None) -> list[np.ndarray]:
    """``STEPS`` actions of ``policy`` driving ``env``; a ``shadow`` policy (built for another
    env) is given the same observations, an empty ``info``, and must answer alike."""
    obs, info = env.reset(seed=seed)
    policy.reset(obs, info)
    if shadow is not None:
        shadow.reset({k: v.copy() for k, v in obs.items()}, {})
    actions = []
    for _ in range(STEPS):
        action = policy(obs)
        if shadow is not None:
            np.testing.assert_array_equal(shadow({k: v.copy() for k, v in obs.items()}), action)
        actions.append(action.copy())
        obs, _, terminated, _, _ = env.step(action)
        assert not terminated
    return actions


# the model-based controllers on every env of ENVS; the learned ones on the envs they have a
# checkpoint for (docs/learning.md §8)
CASES = [(env_id, name) for name in default_controller_names() for env_id in ENVS] + [
    ("wip_gym/Planar-v0", name)
    for name in controller_names()
    if name not in default_controller_names()
]


@pytest.mark.parametrize(("env_id", "name"), CASES)
def test_torques_come_from_the_observation_alone(env_id: str, name: str) -> None:
    today = _make(env_id)
    off = _make(env_id, **OFF)
    noisy = _make(env_id, sensor_noise=1.0)
    # the shadow's env is never stepped: its simulator stays at its construction state
    bystander = _make(env_id)
    reference = _episode(today, make_policy(name, today), seed=3)
    with_off = _episode(off, make_policy(name, off), seed=3)
    for k, (a, b) in enumerate(zip(reference, with_off, strict=True)):
        np.testing.assert_array_equal(a, b, err_msg=f"{name}: step {k} with every argument off")
    sensed = _episode(noisy, make_policy(name, noisy), seed=3, shadow=make_policy(name, bystander))
    changed = [not np.array_equal(a, b) for a, b in zip(reference, sensed, strict=True)]
    assert all(changed), f"{name}: torques unchanged by sensor noise at steps {changed}"
