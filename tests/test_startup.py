"""The first steps of an episode: the robot stands on its wheels' contacts from the reset."""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import wip_gym  # noqa: F401
from controllers import registry
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
