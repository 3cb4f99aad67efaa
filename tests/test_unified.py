"""The hierarchical (unified) controller closed loop: the cup carried to the goal."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from controllers.hierarchical import HierarchicalConfig, HierarchicalController, tilt_toward


def test_tilt_toward_the_specific_force() -> None:
    R = tilt_toward(np.array([9.81, 0.0]), max_tilt_deg=90.0)
    normal = R @ np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(normal, np.array([1.0, 0.0, 1.0]) / np.sqrt(2), atol=1e-12)
    bounded = tilt_toward(np.array([9.81, 0.0]), max_tilt_deg=10.0) @ np.array([0.0, 0.0, 1.0])
    assert np.degrees(np.arccos(bounded[2])) == pytest.approx(10.0)
    np.testing.assert_allclose(tilt_toward(np.zeros(2), 20.0), np.eye(3))


def run(env_id: str, goal, mode: str, seconds: float, **env_kwargs) -> dict:
    env = gym.make(env_id, goal=goal, **env_kwargs)
    obs, info = env.reset(seed=0)
    policy = HierarchicalController.for_env(env, HierarchicalConfig(tray_mode=mode))
    policy.reset(obs, info)
    assert policy.plan.violations == ()
    peaks = {"tilt": 0.0, "friction": 0.0}
    for _ in range(int(seconds / env.unwrapped.dt)):
        obs, _, terminated, _, info = env.step(policy(obs))
        assert not terminated, info
        peaks["tilt"] = max(peaks["tilt"], info["tray_tilt_deg"])
        peaks["friction"] = max(peaks["friction"], info["cup_friction_use"])
    diagnostics = policy.diagnostics
    assert diagnostics["qp_failures"][-1] == 0
    assert diagnostics["mpc_rejected"][-1] == 0
    return {**info, **peaks}


@pytest.fixture(scope="module")
def planar_runs() -> dict[str, dict]:
    return {
        mode: run("wip_gym/PlanarTray-v0", 2.0, mode, 9.0) for mode in ("level", "specific_force")
    }


@pytest.mark.parametrize("mode", ["level", "specific_force"])
def test_planar_tray_reaches_the_goal_with_the_cup(planar_runs: dict, mode: str) -> None:
    info = planar_runs[mode]
    assert info["goal_distance"] < 0.05 and abs(info["xd"]) < 0.05
    assert info["cup_on_tray"]


def test_level_mode_keeps_the_tray_level(planar_runs: dict) -> None:
    assert planar_runs["level"]["tilt"] < 5.0


def test_waiter_comes_less_close_to_slipping(planar_runs: dict) -> None:
    assert planar_runs["specific_force"]["friction"] < planar_runs["level"]["friction"]


def test_unified_keeps_the_cup_when_a_payload_appears_in_the_hand() -> None:
    # 3 kg in the hand at 2.5 s (mid-drive), unknown to the nominal model: without the
    # estimate of the hand tasks' unmodelled acceleration the tray tipped 38 deg and the cup
    # fell at 3.5 s (README); 6 s covers the braking that tipped it and the stop
    info = run("wip_gym/PlanarTray-v0", 2.0, "level", 6.0, payload_mass=3.0, payload_time=2.5)
    assert info["cup_on_tray"] and info["tilt"] < 5.0


# KrangTray-v0: the goal ahead, and 1.5 m to either side (the plan turns toward the goal
# while it drives). 7.5 s: every run has arrived and settled by 7 s (goal distance under
# 1.5 cm, speed under 2 cm/s, measured).
KRANG_GOALS = [(2.0, 0.0), (2.0, 1.5), (2.0, -1.5)]
KRANG_SECONDS = 7.5


@pytest.fixture(scope="module")
def krang_run():
    """One Krang episode per (goal, mode), run on first use and shared by the tests."""
    runs: dict[tuple, dict] = {}

    def get(goal: tuple[float, float], mode: str) -> dict:
        if (goal, mode) not in runs:
            runs[goal, mode] = run("wip_gym/KrangTray-v0", goal, mode, KRANG_SECONDS)
        return runs[goal, mode]

    return get


@pytest.mark.parametrize("goal", KRANG_GOALS)
def test_krang_level_tray_reaches_the_goal_with_the_cup(krang_run, goal) -> None:
    info = krang_run(goal, "level")
    assert info["goal_distance"] < 0.05 and abs(info["xd"]) < 0.05
    assert info["cup_on_tray"] and info["tilt"] < 5.0


@pytest.mark.parametrize("goal", KRANG_GOALS)
def test_krang_waiter_reaches_the_goal_and_comes_less_close_to_slipping(krang_run, goal) -> None:
    waiter = krang_run(goal, "specific_force")
    assert waiter["goal_distance"] < 0.05 and abs(waiter["xd"]) < 0.05
    assert waiter["cup_on_tray"]
    assert waiter["friction"] < krang_run(goal, "level")["friction"]
