"""The decoupled controllers: Krang 2014 as published (``decoupled``) and our LQR
(``decoupled-lqr``): their gains against the linearised model, the LQR's Riccati solution, the
minimum-jerk reference, and the closed loop."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from benchmarks.rollout import rollout
from controllers.baselines.decoupled import (
    BAL_LO_AMPS,
    DecoupledConfig,
    DecoupledController,
    DecoupledLQRConfig,
    DecoupledLQRController,
)
from controllers.baselines.lqr import dlqr, zero_order_hold
from controllers.baselines.minimum_jerk import GoalReference, MinimumJerk
from controllers.simplified.wipm import linearize, params_from_lambda, planar_torque_dynamics


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
def test_lqr_closed_loop_is_stable_and_solves_the_riccati_equation(env_id: str) -> None:
    env = gym.make(env_id)
    obs, info = env.reset(seed=0)
    policy = DecoupledLQRController.for_env(env)
    policy.reset(obs, info)
    Ad, Bd, Q, R, P = policy.riccati
    K = policy.gains
    # the discrete algebraic Riccati equation, to a relative residual of 1e-9
    residual = (
        Ad.T @ P @ Ad - P - Ad.T @ P @ Bd @ np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad) + Q
    )
    assert np.abs(residual).max() < 1e-9 * np.abs(P).max()
    assert np.all(np.linalg.eigvalsh(0.5 * (P + P.T)) > 0)
    # closed loop: inside the unit circle at the control step, and the same gain on the
    # continuous-time model puts every eigenvalue in the left half-plane
    assert np.abs(np.linalg.eigvals(Ad - Bd @ K)).max() < 1.0
    A, B = policy.continuous_model
    assert np.linalg.eigvals(A - B @ K).real.max() < 0.0
    # the open loop is unstable (the pendulum): the gain does the work
    assert np.linalg.eigvals(A).real.max() > 0.1


@pytest.mark.parametrize("env_id", ["wip_gym/WIP-v0", "wip_gym/Planar-v0"])
def test_krang_2014_gains_stabilise_the_linearised_model(env_id: str) -> None:
    """BAL_LO converted to wheel torque, signs as ``decoupled`` applies them: the continuous
    closed loop of the planar WIPM (state theta, thetad, x, xd) is stable."""
    env = gym.make(env_id)
    obs, info = env.reset(seed=0)
    policy = DecoupledController.for_env(env)
    robot = policy.robot
    robot.update(obs["qpos"], obs["qvel"])
    params = params_from_lambda(robot.wipm_parameters())
    A, B = (
        np.asarray(a)
        for a in linearize(
            lambda s, u, p: planar_torque_dynamics(s, u[0], p), np.zeros(4), np.zeros(1), params
        )
    )
    k = DecoupledConfig().wheel_gains
    r = robot.layout.wheel_radius
    # total wheel torque = 2 (k0 theta + k1 thetad + k2 x / r + k3 xd / r)
    K = 2.0 * np.array([[k[0], k[1], k[2] / r, k[3] / r]])
    assert np.linalg.eigvals(A + B @ K).real.max() < 0.0
    assert np.linalg.eigvals(A - B @ K).real.max() > 0.0  # the other sign does not balance
    assert np.allclose(k[:4], 1.2711 * np.array(BAL_LO_AMPS[:4]))
    assert k[0] == pytest.approx(352.6, abs=0.05) and k[1] == pytest.approx(78.7, abs=0.05)
    assert k[2] / 0.25 == pytest.approx(37.9, abs=0.05)
    assert k[3] / 0.25 == pytest.approx(92.7, abs=0.05)


def test_ill_posed_posture_raises() -> None:
    """A CoM on the axle (zero pendulum length) leaves the LQR without a pendulum to balance."""
    env = gym.make("wip_gym/WIP-v0")
    obs, info = env.reset(seed=0)
    policy = DecoupledLQRController.for_env(env)
    model = policy.robot.model
    model.body_ipos[policy.robot.layout.base_body] = 0.0  # CoM exactly at the axle
    with pytest.raises(ValueError, match="ill-posed"):
        policy.reset(obs, info)


def run_closed_loop(env_id: str, controller: str, config, seconds: float, **env_kwargs):  # noqa: ANN001, ANN201
    """One episode through the one rollout; it must run its whole duration."""
    episode = rollout(env_id, env_kwargs, controller, config, 0, seconds)
    assert episode.metrics["sim_time_s"] == pytest.approx(seconds), episode.metrics
    assert not episode.metrics["fell"]
    return episode


@pytest.mark.parametrize("env_id", ["wip_gym/WIP-v0", "wip_gym/Planar-v0"])
def test_krang_2014_reaches_a_2m_goal_and_stops(env_id: str) -> None:
    episode = run_closed_loop(env_id, "decoupled", DecoupledConfig(), 15.0, goal=2.0)
    policy = episode.policy
    # Krang 2014's law, rebuilt from the plan and the measured state: each wheel gets
    # K . [theta - 0, thetad - 0, (x - x_plan) / R, (xd - xd_plan) / R] (the plan's lean is
    # not tracked; planar: no spin term)
    diag, plan, k = policy.diagnostics, policy.plan, policy.config.wheel_gains
    radius = policy.robot.layout.wheel_radius
    planned = [plan.sample(t) for t in diag["t"]]
    x_plan = np.array([p["x"] for p in planned])
    xd_plan = np.array([p["xd"] for p in planned])
    law = (
        k[0] * diag["theta"]
        + k[1] * diag["thetad"]
        + k[2] * (diag["x"] - x_plan) / radius
        + k[3] * (diag["xd"] - xd_plan) / radius
    )
    if env_id == "wip_gym/Planar-v0":
        assert np.abs([p["theta"] for p in planned]).max() > 0.01  # a lean it does not track
    wheels = diag["torque"][:, :2]
    # no current clamp acts on this drive: the law as it is (tests/test_krang_current_limits.py)
    assert np.abs(diag["wheel_current"]).max() < 50.0
    assert policy.counters["wheel_current_clamped_steps"] == 0
    np.testing.assert_allclose(wheels, np.stack([law, law], axis=1), rtol=0, atol=1e-9)
    assert episode.metrics["goal_reached"]  # within 5 cm and 5 cm/s to the episode's end


def test_integral_action_reaches_the_goal_with_an_unmodelled_payload() -> None:
    """Krang with 2 kg in the hand that the nominal model does not know."""
    episode = run_closed_loop(
        "wip_gym/Krang-v0",
        "decoupled-lqr",
        DecoupledLQRConfig(model="nominal"),
        18.0,
        goal=(2.0, 0.0),
        payload_mass=2.0,
    )
    assert episode.policy.robot.model.body("payload").mass[0] == 0.0
    assert episode.metrics["goal_reached"] and episode.metrics["final_goal_error_m"] < 0.05
