"""The env's fast path (the compiled ``wip_gym.envs.measures.env_measures``) against its readable
definition (``wip_gym.envs.step_reference``), step by step, on the states of controlled episodes
on every env and in the tray variants whose branches the defaults leave out (a free tray, a
push, a payload appearing in the hand, a cup that is lost):

* at every step, the readable measures of the fast env's own data equal its compiled ones;
* an env made on the readable path (``wip_gym.mujoco_c.set_fast_path``) and the fast env, run
  in lockstep with the same actions, give the same observation, reward, termination and info
  (and the same physics, to the bit), and each reward term is its definition's value.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from controllers.registry import make_policy
from wip_gym import mujoco_c
from wip_gym.envs import measures as ms
from wip_gym.envs.base import WIPEnv
from wip_gym.envs.step_reference import friction_use, measures

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


def readable_env(env_id: str, **kwargs: Any) -> gym.Env[Any, Any]:
    """``gym.make(env_id, **kwargs)`` on the readable path."""
    mujoco_c.set_fast_path(False)
    try:
        return gym.make(env_id, **kwargs)
    finally:
        mujoco_c.set_fast_path(None)


def _readable_measures(base: WIPEnv) -> np.ndarray:
    """The readable measures of the env's current data (its kinematics are recomputed: the
    same as the step's)."""
    out = base._measures.copy()
    measures(base.model, base.data, base._measure_ints, base._measure_floats, out)
    return out


def _check_rewards(base: WIPEnv, action: np.ndarray, info: dict[str, Any], prev: float) -> float:
    """Each reward term is its definition's value; returns the reward."""
    progress_w, ctrl_w, fall_pen, cup_pen = base._weights
    scaled = action / base._action_scale
    expected = {
        "reward_progress": progress_w * (prev - info["goal_distance"]),
        "reward_ctrl": -ctrl_w * float(scaled @ scaled) * base.dt,
        "reward_fall": -fall_pen if info["fallen"] else 0.0,
    }
    for key, value in expected.items():
        _assert_same(info[key], value, key)
    assert info["reward_cup_loss"] in (0.0, -cup_pen)
    return sum(info[key] for key in (*expected, "reward_cup_loss"))


@pytest.mark.parametrize(("env_id", "kwargs"), CASES)
def test_the_fast_step_equals_its_readable_definition(env_id: str, kwargs: dict[str, Any]) -> None:
    env = gym.make(env_id, **kwargs)  # the fast path
    ref = readable_env(env_id, **kwargs)  # the readable path, in lockstep
    base, ref_base = env.unwrapped, ref.unwrapped
    assert base._measure_table is not None and ref_base._measure_table is None
    obs, info = env.reset(seed=1)
    ref_obs, ref_info = ref.reset(seed=1)
    _assert_same(obs, ref_obs, "reset obs")
    _assert_same(info, ref_info, "reset info")
    policy = make_policy("unified", env)
    policy.reset(obs, info)
    rng = np.random.default_rng(0)
    low, high = base.action_space.low, base.action_space.high
    steps = round(DURATION_S / base.dt)
    seen = {"fallen": False, "cup_lost": False}
    throw = CUP_THROWS.get(CASES.index((env_id, kwargs)))
    prev = info["goal_distance"]
    for n in range(steps):
        if n == throw:  # both envs' cups leave the plate with the same velocity
            for b in (base, ref_base):
                b.data.qvel[b._cup_dof : b._cup_dof + 6] += (1.5, 0.5, 1.0, 3.0, -2.0, 1.0)
        action = np.asarray(policy(obs), dtype=np.float64)
        if n % 7 == 3:  # now and then a kick, to leave the controller's neighbourhood
            action = np.clip(action + rng.normal(0.0, 0.3, action.shape) * high, low, high)
        out = env.step(action)
        compiled = base._measures.copy()
        np.testing.assert_allclose(
            _readable_measures(base), compiled, rtol=1e-12, atol=1e-12, err_msg=f"step {n}"
        )
        ref_out = ref.step(action.copy())
        for name, new, old in zip(
            ("obs", "reward", "terminated", "truncated", "info"), out, ref_out, strict=True
        ):
            _assert_same(new, old, f"step {n} {name}")
        np.testing.assert_array_equal(base.data.qpos, ref_base.data.qpos)
        np.testing.assert_array_equal(base.data.qvel, ref_base.data.qvel)
        assert base._cup_lost == ref_base._cup_lost
        obs, info = out[0], out[4]
        _assert_same(out[1], _check_rewards(base, action, info, prev), f"step {n} reward")
        prev = info["goal_distance"]
        seen["fallen"] |= info["fallen"]
        seen["cup_lost"] |= base._cup_lost
        if out[2]:
            break
    assert seen["fallen"] == (kwargs.get("push_force", 0.0) in (3000.0, -2000.0))
    assert seen["cup_lost"] == (throw is not None)
    # the overlay's numbers read the same state
    shown, ref_shown = base.overlay_values(), ref_base.overlay_values()
    _assert_same(dataclasses.asdict(shown), dataclasses.asdict(ref_shown), "overlay")
    _assert_same(shown.goal_distance, info["goal_distance"], "overlay goal_distance")
    if base._tray:
        _assert_same(shown.tray_tilt_deg, info["tray_tilt_deg"], "overlay tray_tilt_deg")
        used = friction_use(
            base.model, base.data, base._cup_geoms, base._tray_geom, base._cup_friction
        )
        _assert_same(shown.friction_use, used, "overlay friction_use")
        _assert_same(used, info["cup_friction_use"], "friction_use")
    env.close()
    ref.close()


def test_the_readable_measures_fill_every_entry() -> None:
    """Every entry of the measures is written by the readable definition on a tray task (a
    vector of NaN comes back without one), and is the layout's."""
    env = gym.make("wip_gym/KrangTray-v0", tray_attachment="free")
    env.reset(seed=2)
    base = env.unwrapped
    out = np.full(ms.N_OUT, np.nan)
    measures(base.model, base.data, base._measure_ints, base._measure_floats, out)
    assert np.isfinite(out).all()
    np.testing.assert_allclose(out, base._measures, rtol=1e-12, atol=1e-12)
    assert ms.OUT.cup_friction_use == ms.N_OUT - 1
    env.close()
