"""The first steps of an episode: the robot stands on its wheels' contacts from the reset, and
the decoupled controllers' hold takes over from the reset state
(``controllers.baselines.stopping_hold``) instead of stopping the joints in one step. Together
they keep ``decoupled-mpc``'s cup friction use of the first 0.1 s below its episode's 99th
percentile plus 0.1 (docs/controllers.md §3)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import wip_gym  # noqa: F401
from benchmarks.overrides import resolve_run
from benchmarks.rollout import rollout
from controllers import registry
from controllers.baselines.stopping_hold import StoppingHold, VelocityStop
from controllers.low_level.posture import PostureHold
from wip_gym.envs.base import WHEEL_RESET_DEPTH, wip_env


def _floor_force(env: gym.Env) -> tuple[float, list[float]]:
    """The floor's total normal force on the robot (N) and its contacts' distances."""
    base = wip_env(env)
    m, d = base.model, base.data
    floor = m.geom("floor").id
    total, distances = 0.0, []
    for i in range(d.ncon):
        contact = d.contact[i]
        if floor in (contact.geom1, contact.geom2):
            force = np.zeros(6)
            mujoco.mj_contactForce(m, d, i, force)
            total += force[0]
            distances.append(float(contact.dist))
    return total, distances


def test_the_wheels_carry_the_robot_from_the_reset() -> None:
    """WIP-v0, one rigid body on two wheels: at the reset its wheels are WHEEL_RESET_DEPTH into
    the floor and the floor carries its weight (at distance 0 the contacts carried nothing and
    the robot dropped in the first step)."""
    env = gym.make("wip_gym/WIP-v0")
    env.reset(seed=0)
    m = wip_env(env).model
    force, distances = _floor_force(env)
    assert distances == pytest.approx([-WHEEL_RESET_DEPTH] * 2, abs=1e-12)
    weight = -m.opt.gravity[2] * float(m.body_mass.sum())
    assert force == pytest.approx(weight, rel=0.01)


@pytest.mark.parametrize("env_id", ["wip_gym/PlanarTray-v0", "wip_gym/KrangTray-v0"])
def test_the_first_step_does_not_drop_the_robot(env_id: str) -> None:
    """Under decoupled-mpc the base's vertical speed after the first steps stays below 2 mm/s
    (the drop onto the wheels gave 17 to 20 mm/s)."""
    env = gym.make(env_id)
    observation, info = env.reset(seed=1)
    policy = registry.make_policy("decoupled-mpc", env)
    policy.reset(observation, info)
    lay = wip_env(env).robot.layout
    z_dof = lay.root_dof + (1 if lay.planar else 2)
    speeds = []
    for _ in range(5):
        observation, *_ = env.step(policy(observation))
        speeds.append(abs(float(observation["qvel"][z_dof])))
    env.close()
    assert max(speeds) < 2e-3, speeds


# ------------------------------------------------------------------ the hold's reference
def test_velocity_stop_profile() -> None:
    q0, v0, T = np.array([0.3, -1.2]), np.array([0.01, -0.02]), 0.1
    stop = VelocityStop(q0, v0, T)
    q, v, a = stop(0.0)
    np.testing.assert_array_equal(q, q0)
    np.testing.assert_array_equal(v, v0)
    np.testing.assert_array_equal(a, 0.0)
    for t in (T, 2 * T):  # at rest where the stop ends, half the way v0 would have gone in T
        q, v, a = stop(t)
        np.testing.assert_allclose(q, q0 + v0 * T / 2, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(v, 0.0)
        np.testing.assert_array_equal(a, 0.0)
    t = np.linspace(0.0, 1.5 * T, 30001)
    q, v, a = (np.array(x) for x in zip(*(stop(ti) for ti in t), strict=True))
    np.testing.assert_allclose(np.gradient(q, t, axis=0), v, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.gradient(v, t, axis=0), a, rtol=0, atol=1e-5)
    # the minimum-jerk stop's peak deceleration, 15/8 v0 / T, at mid-stop
    np.testing.assert_allclose(np.abs(a).max(axis=0), 1.875 * np.abs(v0) / T, rtol=1e-6)
    step = VelocityStop(q0, v0, 0.0)(0.0)
    np.testing.assert_array_equal(step[0], q0)
    np.testing.assert_array_equal(step[1], 0.0)
    with pytest.raises(ValueError, match="duration"):
        VelocityStop(q0, v0, -0.1)
    with pytest.raises(ValueError, match="shape"):
        VelocityStop(q0, v0[:1], 0.1)
    with pytest.raises(ValueError, match="t must be"):
        stop(-1e-3)


def test_the_holds_reference_starts_at_the_reset_state() -> None:
    """decoupled-mpc: the reference's initial position and velocity are the reset's joint
    positions and velocities (the reset's noise, nonzero), as the env made them."""
    env = gym.make("wip_gym/KrangTray-v0")
    observation, info = env.reset(seed=3)
    policy = registry.make_policy("decoupled-mpc", env)
    policy.reset(observation, info)
    hold = policy._posture
    assert isinstance(hold, StoppingHold) and hold.stop is not None
    # the reset's minimal state, from MuJoCo's own state by a fresh model of the env's robot
    robot = wip_env(env).robot
    robot.update(observation["qpos"], observation["qvel"])
    first = robot.layout.index_q1 + 1
    q, v, a = hold.stop(0.0)
    np.testing.assert_allclose(q, robot.q[first:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(v, robot.nu[first:], rtol=0, atol=1e-12)
    assert np.abs(v).min() > 0 and np.abs(v).max() <= wip_env(env).reset_noise_scale
    np.testing.assert_array_equal(a, 0.0)
    assert hold.stop.duration == policy.config.posture_stop_time_s == 0.1
    env.close()


@pytest.mark.parametrize("controller", ["decoupled", "decoupled-lqr"])
def test_the_5_hz_holds_stop_in_one_step(controller: str) -> None:
    """decoupled and decoupled-lqr keep the step stop (their 5 Hz step does not show in the
    cup's friction peak): from t = 0 their reference is the reset posture at rest."""
    env = gym.make("wip_gym/PlanarTray-v0")
    observation, info = env.reset(seed=3)
    policy = registry.make_policy(controller, env)
    policy.reset(observation, info)
    hold = policy._posture
    assert isinstance(hold, StoppingHold) and hold.stop is not None
    assert hold.stop.duration == policy.config.posture_stop_time_s == 0.0
    q, v, a = hold.stop(0.0)
    np.testing.assert_array_equal(q, hold.posture)
    np.testing.assert_array_equal(v, 0.0)
    env.close()


@pytest.mark.parametrize("computed_torque", [False, True])
def test_stopping_hold_against_posture_hold(computed_torque: bool) -> None:
    """On random states of Krang: at stop time 0 the hold is ``PostureHold``'s; at the reset
    (t = 0) its PD term is zero (no stop asked); after the stop it is ``PostureHold``'s about
    the stop's end; the torques realise the commanded joint accelerations in MuJoCo."""
    env = gym.make("wip_gym/Krang-v0")
    observation, info = env.reset(seed=5)
    robot = registry.make_policy("decoupled", env).robot
    rng = np.random.default_rng(0)
    robot.update(observation["qpos"], observation["qvel"])
    first = robot.layout.index_q1 + 1
    base = rng.normal(size=first) if computed_torque else None
    args: Any = (base,) if computed_torque else ()

    step_hold, posture = StoppingHold(20.0, 1.0, 0.0), PostureHold(20.0, 1.0)
    step_hold.reset(robot)
    posture.reset(robot)
    smooth = StoppingHold(20.0, 1.0, 0.1)
    smooth.reset(robot)
    assert smooth.stop is not None
    # at the reset state and t = 0 nothing is asked beyond the bias (and base feed-forward)
    at_reset = smooth.torques(robot, *args, t=0.0)
    expected = robot.h[first:] + (robot.A[first:, :first] @ base if base is not None else 0.0)
    np.testing.assert_allclose(at_reset, expected, rtol=0, atol=1e-9)
    end = PostureHold(20.0, 1.0)
    end.reset(robot)
    end.posture = smooth.stop(0.1)[0]
    for _ in range(5):
        q, nu = robot.q.copy(), robot.nu.copy()
        q[first:] += rng.uniform(-0.05, 0.05, len(q) - first)
        nu[first:] += rng.uniform(-0.2, 0.2, len(nu) - first)
        robot.update(*robot.full_state(q, nu))
        np.testing.assert_allclose(
            step_hold.torques(robot, *args, t=0.3), posture.torques(robot, *args), atol=1e-9
        )
        np.testing.assert_allclose(
            smooth.torques(robot, *args, t=0.2), end.torques(robot, *args), atol=1e-9
        )
    # mid-stop: the torques give the commanded joint accelerations (MuJoCo the referee)
    t = 0.04
    tau = smooth.torques(robot, *args, t=t)
    if computed_torque:
        q_ref, qd_ref, qdd_ref = smooth.stop(t)
        w = 2 * np.pi * 20.0
        wanted = qdd_ref - w**2 * (robot.q[first:] - q_ref) - 2 * w * (robot.nu[first:] - qd_ref)
        # A nu_dot + h = [base rows; tau] with the base's accelerations given: the joints' rows
        A, h = robot.A, robot.h
        realised = np.linalg.solve(A[first:, first:], tau - h[first:] - A[first:, :first] @ base)
        np.testing.assert_allclose(realised, wanted, rtol=1e-9, atol=1e-9)
    with pytest.raises(ValueError, match="needs t"):
        smooth.torques(robot, *args)
    env.close()


# ------------------------------------------------------------------ the target, in closed loop
@pytest.mark.parametrize(
    ("env_id", "preset", "seed", "duration"),
    [("wip_gym/PlanarTray-v0", None, 1, 25.0), ("wip_gym/KrangTray-v0", "paper", 1, 15.0)],
)
def test_decoupled_mpc_starts_without_a_jerk(
    env_id: str, preset: str | None, seed: int, duration: float
) -> None:
    """The seeds whose start was worst (use 1.0 at 2 ms on PlanarTray-v0, 0.99 at 3 ms on the
    paper's Krang, against p99s of 0.27 and 0.53): the cup's friction use over the first 0.1 s
    stays below the episode's 99th percentile plus 0.1, the whole episode kept."""
    spec = resolve_run(env_id, ["decoupled-mpc"], preset)
    use: list[float] = []

    def record(env: gym.Env, info: dict[str, Any], n: int) -> None:
        if n > 0:
            use.append(float(info["cup_friction_use"]))

    episode = rollout(
        env_id,
        spec.env_kwargs,
        "decoupled-mpc",
        spec.configs["decoupled-mpc"],
        seed,
        duration,
        on_step=record,
    )
    assert episode.metrics["cup_kept"] and not episode.metrics["fell"]
    use_ = np.array(use)
    assert len(use_) == round(duration / 0.001)
    assert np.percentile(use_, 99) == pytest.approx(episode.metrics["cup_friction_use_p99"])
    start = use_[:100].max()
    assert start < episode.metrics["cup_friction_use_p99"] + 0.1, (start, use_[:10])
