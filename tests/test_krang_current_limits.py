"""Krang 2014's published current clamps in ``decoupled`` (docs/AUTHORS_CONFIG.md §5.2): the
spin term at +-30 A, then each wheel's current at +-50 A, at 1.2711 N m/A; ``u_theta`` and
``u_x`` without a clamp of their own. Each case is a state built for it, fed to the policy as an
observation, against the law computed here from the state's own ``theta`` and the plan."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from numpy.typing import NDArray

import wip_gym  # noqa: F401
from benchmarks.rollout import rollout
from controllers.baselines.decoupled import (
    BAL_LO_AMPS,
    DecoupledConfig,
    DecoupledController,
    DecoupledLQRController,
    krang_currents,
)
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]
AMP = 1.2711  # N m per amp of one wheel's motor (docs/AUTHORS_CONFIG.md §1.5)


def test_the_clamps_are_the_published_ones() -> None:
    config = DecoupledConfig()
    assert config.spin_current_limit_amps == 30.0
    assert config.wheel_current_limit_amps == 50.0
    assert config.torque_per_amp == AMP
    with pytest.raises(ValueError, match="wheel_current_limit_amps"):
        DecoupledConfig(wheel_current_limit_amps=0.0)
    with pytest.raises(ValueError, match="spin_current_limit_amps"):
        DecoupledConfig(spin_current_limit_amps=-1.0)


def test_krang_currents_clamps_the_spin_term_then_each_wheel() -> None:
    # u_theta and u_x unclamped by themselves: 40 A of theta passes whole
    free = krang_currents(40.0, -5.0, 10.0, 30.0, 50.0)
    assert free.wheels == (45.0, 25.0)
    assert not free.spin_clamped and not free.wheel_clamped
    # the spin term at 30 A before the sum
    spin = krang_currents(0.0, 0.0, -45.0, 30.0, 50.0)
    assert spin.wheels == (-30.0, 30.0) and spin.spin == -45.0
    assert spin.spin_clamped and not spin.wheel_clamped
    # then each wheel at 50 A: the right wheel alone here
    wheel = krang_currents(30.0, 5.0, -30.0, 30.0, 50.0)
    assert wheel.wheels == (5.0, 50.0)
    assert wheel.wheel_clamped and not wheel.spin_clamped
    both = krang_currents(60.0, 0.0, 40.0, 30.0, 50.0)
    assert both.wheels == (50.0, 30.0) and both.spin_clamped and both.wheel_clamped


def _policy(env_id: str) -> tuple[DecoupledController, dict[str, Array]]:
    env = gym.make(env_id)
    observation, info = env.reset(seed=0)
    policy = DecoupledController.for_env(env)
    policy.reset(observation, info)
    env.close()
    return policy, observation


def _observation(policy: DecoupledController, q: Array, nu: Array) -> dict[str, Any]:
    qpos, qvel = policy.robot.full_state(q, nu)
    return {"qpos": qpos, "qvel": qvel}


def _leaning(policy: DecoupledController, u_theta: float) -> tuple[dict[str, Any], float]:
    """An observation at rest on the plan's start whose ``theta`` gives ``u_theta`` amps of
    K0 theta (the body pitched about the axle), with that ``theta`` measured by a fresh model."""
    robot = policy.robot
    q = robot.q.copy()
    q[robot.layout.index_x] = policy.plan.sample(0.0)["x"] if policy.plan else 0.0
    nu = np.zeros(robot.layout.n_min)
    robot.update(*robot.full_state(q, nu))
    # theta moves one for one with the base pitch (the body turns rigidly about the axle)
    q[robot.layout.index_q1] += u_theta / BAL_LO_AMPS[0] - robot.theta
    observation = _observation(policy, q, nu)
    check = RobotModel(policy.robot.model)
    check.update(observation["qpos"], observation["qvel"])
    return observation, BAL_LO_AMPS[0] * check.theta


@pytest.mark.parametrize("u_theta", [40.0, 60.0, -60.0])
def test_a_theta_term_beyond_the_wheel_clamp_gives_the_clamped_torque(u_theta: float) -> None:
    """40 A of ``u_theta`` passes unclamped (the published code has no clamp on it); +-60 A is
    clamped by each wheel's 50 A: exactly 63.555 N m on both wheels, counted once."""
    policy, _ = _policy("wip_gym/PlanarTray-v0")
    observation, amps = _leaning(policy, u_theta)
    assert amps == pytest.approx(u_theta, abs=1e-6)
    action = policy(observation)
    wheels = action[list(policy.robot.layout.wheel_actuators)]
    # the plan starts at the reset state: x and xd on it, u_x = 0 to round-off
    u_x = policy.diagnostics["current_x"][0]
    assert abs(u_x) < 1e-9
    expected = AMP * np.clip(amps + u_x, -50.0, 50.0)
    np.testing.assert_allclose(wheels, [expected, expected], rtol=0, atol=1e-12)
    clamped = abs(u_theta) > 50.0
    if clamped:
        assert abs(wheels[0]) == pytest.approx(50.0 * AMP, abs=1e-12)
    counters = policy.counters
    assert counters["wheel_current_clamped_steps"] == float(clamped)
    assert counters["spin_current_clamped_steps"] == 0.0
    assert counters["clipped_steps"] == 0.0  # 63.6 N m is well inside the wheels' 150


def test_a_spin_rate_beyond_30_amps_is_clamped_before_the_sum() -> None:
    """Krang: a turn at 3 rad/s asks ``-K5 (sep / 2R) psid``, about 41 A; it gets 30 A, added to
    the left wheel and taken from the right."""
    policy, _ = _policy("wip_gym/KrangTray-v0")
    robot, lay = policy.robot, policy.robot.layout
    q = robot.q.copy()
    nu = np.zeros(lay.n_min)
    assert lay.index_psi is not None
    nu[lay.index_psi] = 3.0
    observation = _observation(policy, q, nu)
    action = policy(observation)
    diag = policy.diagnostics
    spin_per_heading = lay.wheel_separation / (2.0 * lay.wheel_radius)
    ref = policy.plan.sample(0.0) if policy.plan else {}
    asked = -BAL_LO_AMPS[5] * spin_per_heading * (3.0 - ref["psid"]) + (
        policy.config.heading_gain_amps * spin_per_heading * (q[lay.index_psi] - ref["psi"])
    )
    assert asked > 35.0
    assert diag["current_spin"][0] == pytest.approx(asked, rel=1e-12)
    common = diag["current_theta"][0] + diag["current_x"][0]
    assert abs(common) < 20.0  # the wheels' clamp is not reached
    wheels = action[list(lay.wheel_actuators)]
    np.testing.assert_allclose(wheels, AMP * np.array([common + 30.0, common - 30.0]), atol=1e-12)
    assert policy.counters["spin_current_clamped_steps"] == 1.0
    assert policy.counters["wheel_current_clamped_steps"] == 0.0


@pytest.mark.parametrize("env_id", ["wip_gym/PlanarTray-v0", "wip_gym/KrangTray-v0"])
def test_no_clamp_acts_in_a_quiet_state(env_id: str) -> None:
    """At the reset state (0.01 rad and rad/s of noise) the currents are a few amps: the wheel
    torques are the unclamped law, nothing is counted."""
    policy, observation = _policy(env_id)
    action = policy(observation)
    diag = policy.diagnostics
    u_theta, u_x, u_spin = (diag[k][0] for k in ("current_theta", "current_x", "current_spin"))
    assert max(abs(u_theta), abs(u_x), abs(u_spin)) < 10.0
    wheels = action[list(policy.robot.layout.wheel_actuators)]
    law = AMP * np.array([u_theta + u_x + u_spin, u_theta + u_x - u_spin])
    np.testing.assert_allclose(wheels, law, rtol=0, atol=1e-12)
    counters = policy.counters
    assert counters["spin_current_clamped_steps"] == counters["wheel_current_clamped_steps"] == 0


def test_the_clamp_counters_reach_the_episode_record() -> None:
    """A wheel limit of 0.01 A clamps every step of a short episode: the rollout's record
    carries the policy's counts."""
    config = DecoupledConfig(wheel_current_limit_amps=0.01)
    episode = rollout("wip_gym/KrangTray-v0", {}, "decoupled", config, 0, 0.02)
    steps = episode.metrics["steps"]
    assert steps == 20
    counters = episode.metrics["counters"]
    assert counters["wheel_current_clamped_steps"] == steps
    assert counters == episode.policy.counters
    assert "spin_current_clamped_steps" in counters
    currents = episode.policy.diagnostics["wheel_current"]
    np.testing.assert_allclose(np.abs(currents), 0.01, rtol=0, atol=1e-15)


def test_decoupled_lqr_has_no_current_clamp() -> None:
    env = gym.make("wip_gym/PlanarTray-v0")
    observation, info = env.reset(seed=0)
    policy = DecoupledLQRController.for_env(env)
    policy.reset(observation, info)
    env.close()
    assert not any("current" in name for name in policy.counters)
