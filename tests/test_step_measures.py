"""The env's compiled step arithmetic (``wip_gym.envs.measures``) without contacts: the same
step as the readable path (``wip_gym.envs.step_reference``), from one compiled version of the
kernel for states with and without contacts; its table of addresses, copies, contacts."""

from __future__ import annotations

import copy
import pickle

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import wip_gym  # noqa: F401
from tests.test_env_step_reference import _assert_same, readable_env
from wip_gym import mujoco_c
from wip_gym.envs.measures import ENV, action_effort, gather_contacts, step_measures
from wip_gym.mujoco_c import contact_layout


def _mujoco_entries(env: object) -> tuple[int, ...]:
    """The env's table's ``mujoco`` row: the addresses of its model and data, then its
    contacts' layout."""
    table = env._measure_table  # type: ignore[attr-defined]
    return tuple(table.arrays[ENV.index.mujoco].tolist())


@pytest.mark.parametrize("env_id", ["wip_gym/Planar-v0", "wip_gym/KrangTray-v0"])
def test_step_in_the_air_matches_the_reference_step(env_id: str) -> None:
    env, ref = gym.make(env_id), readable_env(env_id)
    env.reset(seed=1)
    ref.reset(seed=1)
    base, ref_base = env.unwrapped, ref.unwrapped
    assert base.data.ncon > 0
    for b in (base, ref_base):  # lifted 1 m: nothing touches
        qpos = b.data.qpos.copy()
        qpos[base._layout.root_qpos + (1 if base._layout.planar else 2)] += 1.0
        b.set_state(qpos, b.data.qvel.copy())
    action = 0.1 * env.action_space.high
    for step in range(20):
        new = base.step(action)
        old = ref_base.step(action)
        assert base.data.ncon == 0
        for what, n, o in zip(
            ("obs", "reward", "terminated", "truncated", "info"), new, old, strict=True
        ):
            _assert_same(n, o, f"step {step} {what}")
    assert len(step_measures.signatures) == 1


def test_actions_of_any_layout_use_the_one_compiled_check() -> None:
    env = gym.make("wip_gym/Krang-v0")
    env.reset(seed=0)
    high = env.action_space.high.astype(float)
    read_only = 0.1 * high
    read_only.flags.writeable = False
    strided = np.repeat(0.1 * high, 2)[::2]
    for action in (0.1 * high, read_only, strided, (0.1 * high).astype(np.float32)):
        env.step(action)
    with pytest.raises(ValueError, match="beyond the torque limits"):
        env.step(2.0 * high)
    with pytest.raises(ValueError, match="NaN"):
        env.step(np.full_like(high, np.nan))
    assert len(action_effort.signatures) == 1


def test_a_copied_env_measures_its_own_data() -> None:
    """``env_measures`` reads MuJoCo's buffers through addresses (``address_table``): a copy of
    the env (deepcopy, pickle) must read its own data, not the original's."""
    env = gym.make("wip_gym/KrangTray-v0").unwrapped
    env.reset(seed=0)
    action = 0.1 * env.action_space.high
    for _ in range(5):
        env.step(action)
    for copied in (copy.deepcopy(env), pickle.loads(pickle.dumps(env))):
        addresses = mujoco_c.addresses(copied.model, copied.data)
        assert _mujoco_entries(copied)[:2] == addresses
        assert addresses[1] != mujoco_c.addresses(env.model, env.data)[1]
        assert _mujoco_entries(copied)[2:] == contact_layout(copied.data)
        assert contact_layout(copied.data)[0] != contact_layout(env.data)[0]
        copied.set_state(env.data.qpos.copy(), env.data.qvel.copy())  # the same state
        copied.data.time = env.data.time
        copied.data.qacc_warmstart[:] = env.data.qacc_warmstart  # the solver's start too
        env.set_state(env.data.qpos.copy(), env.data.qvel.copy())
        obs_copy, *_ = copied.step(action)
        obs, *_ = env.step(action)
        np.testing.assert_array_equal(obs_copy["qpos"], obs["qpos"])
        np.testing.assert_array_equal(obs_copy["cup_pose"], obs["cup_pose"])
        copied.step(5.0 * action)  # moves the copy alone
        assert not np.array_equal(copied._measures, env._measures)


def test_the_contacts_stay_where_their_layout_was_taken() -> None:
    """``contact_layout`` is taken once per MjData: MuJoCo keeps the contacts at the start of
    the data's arena, through steps with varying contact counts and a reset."""
    env = gym.make("wip_gym/KrangTray-v0").unwrapped
    env.reset(seed=0)
    layout = contact_layout(env.data)
    counts = set()
    action = 0.3 * env.action_space.high
    for step in range(300):
        env.step(action if step % 50 < 25 else -action)
        counts.add(env.data.ncon)
        assert contact_layout(env.data) == layout
        assert _mujoco_entries(env)[2:] == layout
    env.reset(seed=1)
    assert contact_layout(env.data) == layout
    assert len(counts) > 1  # the count changed along the way


def test_friction_use_with_pyramidal_cones_equals_the_bindings_reading() -> None:
    """The compiled friction use reads the contact-frame forces with ``mj_contactForce``, so a
    model switched to pyramidal cones gives what ``friction_use`` (the bindings) gives."""
    env = gym.make("wip_gym/KrangTray-v0").unwrapped
    env.model.opt.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL
    env.reset(seed=0)
    action = 0.2 * env.action_space.high
    uses = []
    for _ in range(100):
        *_, info = env.step(action)
        uses.append(info["cup_friction_use"])
        assert info["cup_friction_use"] == env._cup_friction_use()
    assert max(uses) > 0.0


def test_gather_contacts_refuses_more_contacts_than_the_arena_holds() -> None:
    env = gym.make("wip_gym/Krang-v0").unwrapped
    env.reset(seed=0)
    for _ in range(5):  # forces of a step taken
        env.step(np.zeros(env.action_space.shape))
    table = env._measure_table.rows
    n = env.data.ncon
    geom, frame, force = gather_contacts(table, n, True)
    np.testing.assert_array_equal(geom, env.data.contact.geom)
    np.testing.assert_array_equal(frame, env.data.contact.frame)
    assert (force[:, 0] > 0).all()  # the wheels on the floor
    assert not gather_contacts(table, n, False)[2].any()  # no forces asked: zeros
    with pytest.raises(ValueError, match="data.ncon"):
        gather_contacts(table, int(contact_layout(env.data)[3]) + 1, False)
