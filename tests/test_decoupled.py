"""The decoupled (Krang 2014) controller: its LQR, its reference, and the closed loop."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from controllers.decoupled import DecoupledConfig, DecoupledController
from controllers.lqr import dlqr, zero_order_hold
from controllers.reference import GoalReference, MinimumJerk


def test_minimum_jerk_profile() -> None:
    profile = MinimumJerk.with_peak_acceleration(2.0, 0.3)
    t = np.linspace(-1.0, profile.end + 1.0, 20001)
    p, v, a = np.array([profile(ti) for ti in t]).T
    assert p[0] == 0.0 and p[-1] == pytest.approx(2.0)
    assert np.abs(a).max() == pytest.approx(0.3, rel=1e-3)
    np.testing.assert_allclose(np.gradient(p, t), v, atol=1e-4)
    np.testing.assert_allclose(np.gradient(v, t), a, atol=1e-3)


def test_goal_reference_turns_then_drives() -> None:
    ref = GoalReference.to_goal(
        np.zeros(2),
        0.0,
        np.array([2.0, 2.0]),
        x0=0.0,
        max_acceleration=0.3,
        max_spin_acceleration=0.5,
        planar=False,
    )
    assert ref.heading.distance == pytest.approx(np.pi / 4)
    assert ref.drive.start == pytest.approx(ref.heading.end)
    end = ref(ref.end + 1.0)
    assert end["x"] == pytest.approx(np.hypot(2.0, 2.0))
    assert end["psi"] == pytest.approx(np.pi / 4)


def test_dlqr_rejects_an_uncontrollable_model() -> None:
    A = np.diag([1.0, 2.0])  # the second mode is unstable and unreachable
    B = np.array([[1.0], [0.0]])
    Ad, Bd = zero_order_hold(A, B, 0.001)
    with pytest.raises(ValueError, match="ill-posed"):
        dlqr(Ad, Bd, np.eye(2), np.eye(1))


@pytest.mark.parametrize("env_id", ["wip_gym/WIP-v0", "wip_gym/Planar-v0", "wip_gym/Krang-v0"])
def test_lqr_stabilises_the_linearised_model(env_id: str) -> None:
    env = gym.make(env_id)
    obs, info = env.reset(seed=0)
    policy = DecoupledController.for_env(env)
    policy.reset(obs, info)
    assert np.abs(np.linalg.eigvals(policy.closed_loop_matrix)).max() < 1.0
    # the open-loop pendulum is unstable: the gains are doing the work
    K = policy.gains
    assert np.all(np.isfinite(K)) and np.abs(K).max() > 0


def test_ill_posed_posture_raises() -> None:
    """A CoM on the axle (zero pendulum length) leaves the LQR without a pendulum to balance."""
    env = gym.make("wip_gym/WIP-v0")
    obs, info = env.reset(seed=0)
    policy = DecoupledController.for_env(env)
    model = policy.robot.model
    model.body_ipos[policy.robot.layout.base_body] = 0.0  # CoM exactly at the axle
    with pytest.raises(ValueError, match="ill-posed"):
        policy.reset(obs, info)


def run_closed_loop(env: gym.Env, policy: DecoupledController, seconds: float) -> dict:
    obs, info = env.reset(seed=0)
    policy.reset(obs, info)
    for _ in range(int(seconds / env.unwrapped.dt)):
        obs, _, terminated, _, info = env.step(policy(obs))
        assert not terminated, info
    return info


@pytest.mark.parametrize("env_id", ["wip_gym/WIP-v0", "wip_gym/Planar-v0"])
def test_reaches_a_2m_goal_and_stops(env_id: str) -> None:
    env = gym.make(env_id, goal=2.0)
    policy = DecoupledController.for_env(env)
    info = run_closed_loop(env, policy, 15.0)
    assert info["goal_distance"] < 0.05
    assert abs(info["xd"]) < 0.05
    assert not info["fallen"]


def test_integral_action_reaches_the_goal_with_an_unmodelled_payload() -> None:
    """Krang with 2 kg in the hand that the nominal model does not know."""
    env = gym.make("wip_gym/Krang-v0", goal=(2.0, 0.0), payload_mass=2.0)
    policy = DecoupledController.for_env(env, DecoupledConfig(model="nominal"))
    assert policy.robot.model.body("payload").mass[0] == 0.0
    info = run_closed_loop(env, policy, 18.0)
    assert info["goal_distance"] < 0.05
    assert abs(info["xd"]) < 0.05
