"""The env's step gives the same observation, reward, termination and info as the step it
replaced (tests/env_step_reference.py keeps that computation), on the states of controlled
episodes on every env, and in the tray variants whose branches the defaults leave out (a free
tray, a push, a payload appearing in the hand, a cup that is lost)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from controllers.registry import make_policy
from tests.env_step_reference import (
    friction_use,
    goal_distance,
    reference_reset_info,
    reference_step,
    tray_tilt_deg,
)

DURATION_S = 0.6
CASES: list[tuple[str, dict[str, Any]]] = [
    ("wip_gym/WIP-v0", {}),
    ("wip_gym/Planar-v0", {}),
    ("wip_gym/Krang-v0", {}),
    ("wip_gym/PlanarTray-v0", {}),
    ("wip_gym/KrangTray-v0", {}),
    # a free tray with a rim, a push, a payload appearing in the hand, a slippery cup
    (
        "wip_gym/KrangTray-v0",
        {
            "tray_attachment": "free",
            "push_force": 60.0,
            "push_time": 0.1,
            "payload_mass": 0.5,
            "payload_time": 0.2,
            "cup_friction": 0.05,
            "terminate_on_cup_loss": False,
        },
    ),
    (
        "wip_gym/PlanarTray-v0",
        {"tray_attachment": "free", "tray_rim": 0.02, "push_force": -40.0, "push_time": 0.05},
    ),
    ("wip_gym/Krang-v0", {"push_force": 3000.0, "push_time": 0.05, "push_duration": 0.2}),
    ("wip_gym/Planar-v0", {"push_force": -2000.0, "push_time": 0.05, "push_duration": 0.2}),
    # a payload without a push (the step's events end when it is in the hand)
    ("wip_gym/Krang-v0", {"payload_mass": 1.0, "payload_time": 0.1}),
]
#: (case index, step): the cup is thrown (its velocity set in both envs) before that step
CUP_THROWS = {4: 150, 5: 300, 6: 200}


def _assert_same(new: Any, old: Any, what: str) -> None:
    assert type(new) is type(old), (what, type(new), type(old))
    if isinstance(old, dict):
        assert list(new) == list(old), (what, list(new), list(old))
        for key in old:
            _assert_same(new[key], old[key], f"{what}[{key!r}]")
    elif isinstance(old, np.ndarray):
        assert new.shape == old.shape and new.dtype == old.dtype, what
        np.testing.assert_allclose(new, old, rtol=1e-12, atol=1e-12, err_msg=what)
    elif isinstance(old, float):
        np.testing.assert_allclose(new, old, rtol=1e-12, atol=1e-12, err_msg=what)
    else:
        assert new == old, (what, new, old)


@pytest.mark.parametrize(("env_id", "kwargs"), CASES)
def test_step_matches_the_reference_step(env_id: str, kwargs: dict[str, Any]) -> None:
    env = gym.make(env_id, **kwargs)  # steps with WIPEnv.step
    ref = gym.make(env_id, **kwargs)  # steps with reference_step, in lockstep
    base, ref_base = env.unwrapped, ref.unwrapped
    obs, info = env.reset(seed=1)
    ref_obs, _ = ref.reset(seed=1)
    _assert_same(obs, ref_obs, "reset obs")
    _assert_same(info, reference_reset_info(ref_base), "reset info")
    policy = make_policy("unified", env)
    policy.reset(obs, info)
    rng = np.random.default_rng(0)
    low, high = base.action_space.low, base.action_space.high
    steps = round(DURATION_S / base.dt)
    seen = {"fallen": False, "cup_lost": False}
    throw = CUP_THROWS.get(CASES.index((env_id, kwargs)))
    for n in range(steps):
        if n == throw:  # both envs' cups leave the plate with the same velocity
            for b in (base, ref_base):
                b.data.qvel[b._cup_dof : b._cup_dof + 6] += (1.5, 0.5, 1.0, 3.0, -2.0, 1.0)
        action = np.asarray(policy(obs), dtype=np.float64)
        if n % 7 == 3:  # now and then a kick, to leave the controller's neighbourhood
            action = np.clip(action + rng.normal(0.0, 0.3, action.shape) * high, low, high)
        out = env.step(action)
        ref_out = reference_step(ref_base, action.copy())
        for name, new, old in zip(
            ("obs", "reward", "terminated", "truncated", "info"), out, ref_out, strict=True
        ):
            _assert_same(new, old, f"step {n} {name}")
        np.testing.assert_array_equal(base.data.qpos, ref_base.data.qpos)
        np.testing.assert_array_equal(base.data.qvel, ref_base.data.qvel)
        assert base._cup_lost == ref_base._cup_lost
        assert base._prev_distance == pytest.approx(ref_base._prev_distance, rel=1e-12, abs=1e-12)
        obs, info = out[0], out[4]
        seen["fallen"] |= info["fallen"]
        seen["cup_lost"] |= base._cup_lost
        if out[2]:
            break
    assert seen["fallen"] == (kwargs.get("push_force", 0.0) in (3000.0, -2000.0))
    assert seen["cup_lost"] == (throw is not None)
    # the overlay's numbers read the same state
    shown = base.overlay_values()
    assert shown.time == ref_base.data.time and shown.cup_lost == ref_base._cup_lost
    _assert_same(shown.goal_distance, goal_distance(ref_base), "overlay goal_distance")
    if base._tray:
        _assert_same(shown.tray_tilt_deg, tray_tilt_deg(ref_base), "overlay tray_tilt_deg")
        used = friction_use(
            ref_base.model,
            ref_base.data,
            ref_base._cup_geoms,
            ref_base._tray_geom,
            ref_base._cup_friction,
        )
        _assert_same(shown.friction_use, used, "overlay friction_use")
    env.close()
    ref.close()
