"""The five environments: Gymnasium's checkers, determinism, rewards, spaces, physics sanity."""

from __future__ import annotations

import copy

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.wrappers import FlattenObservation

import wip_gym

ENV_IDS = list(wip_gym.ENV_IDS)
TRAY_IDS = ["wip_gym/PlanarTray-v0", "wip_gym/KrangTray-v0"]


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_check_env(env_id: str) -> None:
    env = gym.make(env_id)
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_same_seed_same_episode(env_id: str) -> None:
    def run() -> list[np.ndarray]:
        env = gym.make(env_id)
        obs, _ = env.reset(seed=7)
        rng = np.random.default_rng(0)
        trace = [np.concatenate([obs["qpos"], obs["qvel"]])]
        for _ in range(200):
            action = rng.uniform(-0.2, 0.2, env.action_space.shape) * env.action_space.high
            obs, *_ = env.step(action)
            trace.append(np.concatenate([obs["qpos"], obs["qvel"]]))
        env.close()
        return trace

    first, second = run(), run()
    np.testing.assert_array_equal(np.array(first), np.array(second))


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_different_seeds_differ_and_noise_is_nonzero(env_id: str) -> None:
    env = gym.make(env_id)
    a, _ = env.reset(seed=1)
    b, _ = env.reset(seed=2)
    assert not np.allclose(a["qvel"], b["qvel"])
    quiet = gym.make(env_id, reset_noise_scale=0.0)
    c, info = quiet.reset(seed=1)
    assert abs(info["theta"]) < 1e-9  # the CoM starts exactly over the axle
    assert not np.allclose(a["qpos"], c["qpos"])


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_reward_is_sum_of_terms(env_id: str) -> None:
    env = gym.make(env_id)
    env.reset(seed=0)
    rng = np.random.default_rng(1)
    for _ in range(300):
        action = rng.uniform(-0.3, 0.3, env.action_space.shape) * env.action_space.high
        _, reward, terminated, _, info = env.step(action)
        terms = sum(v for k, v in info.items() if k.startswith("reward_"))
        assert reward == terms
        if terminated:
            break


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_zero_torque_falls_and_is_reported(env_id: str) -> None:
    # the falling robot throws the cup off first (a lost cup ends the episode by default)
    kwargs = {"terminate_on_cup_loss": False} if env_id in TRAY_IDS else {}
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    zero = np.zeros(env.action_space.shape)
    for _ in range(5000):
        _, reward, terminated, _, info = env.step(zero)
        if terminated:
            break
    assert terminated and info["fallen"]
    assert info["reward_fall"] < 0


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_flatten_and_vector_env_step(env_id: str) -> None:
    flat = FlattenObservation(gym.make(env_id))
    obs, _ = flat.reset(seed=0)
    assert obs.dtype == np.float64 and obs.ndim == 1
    flat.step(np.zeros(flat.action_space.shape))
    vec = gym.make_vec(env_id, num_envs=2, vectorization_mode="sync")
    obs, _ = vec.reset(seed=0)
    assert obs["qpos"].shape[0] == 2
    vec.step(np.zeros(vec.action_space.shape))
    vec.close()


@pytest.mark.parametrize(
    ("action", "message"),
    [
        (np.full(2, np.nan), "NaN"),
        (np.zeros(3), "shape"),
        (np.array([1000.0, 0.0]), "limits"),
    ],
)
def test_bad_actions_raise(action: np.ndarray, message: str) -> None:
    env = gym.make("wip_gym/WIP-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match=message):
        env.unwrapped.step(action)


def test_bad_kwargs_raise() -> None:
    with pytest.raises(ValueError, match="goal"):
        gym.make("wip_gym/Planar-v0", goal=(1.0, 2.0))
    for friction in (-1.0, 0.0):  # 0: friction use (tangential / (mu normal)) is undefined
        with pytest.raises(ValueError, match="cup_friction"):
            gym.make("wip_gym/PlanarTray-v0", cup_friction=friction)
    with pytest.raises(ValueError, match="mass_randomization"):
        gym.make("wip_gym/Krang-v0", mass_randomization=2.0)


def test_frame_skip_assigned_between_steps_is_checked_and_timed() -> None:
    """``frame_skip`` (MujocoEnv's attribute) assigned after construction: a value that is not
    a positive integer is refused at the next step (``mj_step`` takes 0 or a negative count as
    no step at all), and a valid one steps that many times, its control cost over the new
    step's duration."""
    env = gym.make("wip_gym/Planar-v0").unwrapped
    env.reset(seed=0)
    action = 0.1 * env.action_space.high
    _, _, _, _, once = env.step(action)
    for bad in (0, -3, 1.5):
        env.frame_skip = bad
        with pytest.raises(ValueError, match="frame_skip must be a positive integer"):
            env.step(action)
        env._bind_views()  # as after the env's data or model is replaced: still checked
        with pytest.raises(ValueError, match="frame_skip must be a positive integer"):
            env.step(action)
    env.frame_skip = 2
    time = env.data.time
    _, _, _, _, twice = env.step(action)
    assert env.data.time == pytest.approx(time + 2 * env.model.opt.timestep)
    assert twice["reward_ctrl"] == pytest.approx(2 * once["reward_ctrl"])


@pytest.mark.parametrize("env_id", TRAY_IDS)
def test_tray_starts_level_with_cup_on_it(env_id: str) -> None:
    env = gym.make(env_id, reset_noise_scale=0.0)
    obs, info = env.reset(seed=0)
    assert info["tray_tilt_deg"] < 1e-6
    assert info["cup_on_tray"]
    assert obs["cup_pose"].shape == (7,)


def test_wheel_torque_limit_and_cup_friction_kwargs() -> None:
    env = gym.make("wip_gym/KrangTray-v0", wheel_torque_limit=63.6, cup_friction=0.5)
    np.testing.assert_allclose(env.action_space.high[:2], 63.6, rtol=1e-6)
    assert env.unwrapped.cup_friction == 0.5


def test_push_moves_the_robot_along_the_heading() -> None:
    def final_x(force: float) -> float:
        env = gym.make(
            "wip_gym/WIP-v0",
            push_force=force,
            push_time=0.0,
            push_duration=0.2,
            reset_noise_scale=0.0,
        )
        env.reset(seed=0)
        for _ in range(150):
            _, _, _, _, info = env.step(np.zeros(2))
        return info["x"]

    assert final_x(200.0) > final_x(0.0) + 1e-3
    assert final_x(-200.0) < final_x(0.0) - 1e-3


def test_push_owns_its_bodys_applied_force_only_in_an_env_with_a_push() -> None:
    """Without a push the env leaves ``xfrc_applied`` to the user (a force set on the push
    body stays); with one it writes the push along the heading in its window and zero after."""
    plain = gym.make("wip_gym/Krang-v0")
    plain.reset(seed=0)
    base = plain.unwrapped
    body = base._push_body
    base.data.xfrc_applied[body] = (30.0, -20.0, 0.0, 0.0, 1.0, 0.0)
    for _ in range(3):
        plain.step(np.zeros(plain.action_space.shape))
    np.testing.assert_array_equal(base.data.xfrc_applied[body], (30.0, -20.0, 0.0, 0.0, 1.0, 0.0))

    pushed = gym.make("wip_gym/Krang-v0", push_force=100.0, push_time=0.0, push_duration=0.002)
    _, info = pushed.reset(seed=0)
    base = pushed.unwrapped
    base.data.xfrc_applied[body] = (30.0, -20.0, 0.0, 0.0, 1.0, 0.0)
    pushed.step(np.zeros(pushed.action_space.shape))
    psi = info["psi"]  # the heading at the step's start
    np.testing.assert_allclose(
        base.data.xfrc_applied[body], (100.0 * np.cos(psi), 100.0 * np.sin(psi), 0, 0, 0, 0)
    )
    for _ in range(3):
        pushed.step(np.zeros(pushed.action_space.shape))
    np.testing.assert_array_equal(base.data.xfrc_applied[body], 0.0)


def test_payload_changes_the_mass_when_it_appears() -> None:
    env = gym.make("wip_gym/Krang-v0", payload_mass=2.0, payload_time=0.05)
    env.reset(seed=0)
    model = env.unwrapped.model
    payload = model.body("payload").id
    assert model.body_mass[payload] == 0.0
    positions = []
    for _ in range(60):
        obs, *_ = env.step(np.zeros(env.action_space.shape))
        positions.append(obs["qpos"].copy())
    assert model.body_mass[payload] == 2.0
    # the state carries on through the change (mj_setConst must not touch the env's data)
    jumps = np.abs(np.diff(np.array(positions), axis=0)).max(axis=1)
    assert jumps.max() < 1e-2


def test_a_payload_time_without_a_payload_mass_is_no_payload() -> None:
    env = gym.make("wip_gym/Krang-v0", payload_time=0.05)
    env.reset(seed=0)
    for _ in range(100):  # past payload_time: nothing to put in the hand
        env.step(np.zeros(env.action_space.shape))
    assert not env.unwrapped.payload_visible


def test_mass_randomization_is_seeded() -> None:
    env = gym.make("wip_gym/Krang-v0", mass_randomization=0.1)
    env.reset(seed=3)
    first = env.unwrapped.model.body_mass.copy()
    env.reset(seed=4)
    assert not np.allclose(first, env.unwrapped.model.body_mass)
    env.reset(seed=3)
    np.testing.assert_array_equal(first, env.unwrapped.model.body_mass)


def test_set_const_on_the_scratch_data_equals_a_fresh_datas() -> None:
    """The model's constants after each reset (masses randomised, ``mj_setConst`` on the env's
    one scratch MjData, which episodes leave in any state) equal ``mj_setConst`` on a fresh
    MjData of a copy of the same model, in every array of the model."""
    env = gym.make("wip_gym/KrangTray-v0", mass_randomization=0.1)
    base = env.unwrapped
    for seed in range(3):
        env.reset(seed=seed)
        for _ in range(20):
            env.step(env.action_space.sample() * 0.1)
        scratch = base._scratch_data[1]  # left in another state than setConst's
        scratch.qpos[:] = np.random.default_rng(seed).normal(size=scratch.qpos.shape)
        mujoco.mj_step(base.model, scratch)
        fresh = copy.deepcopy(base.model)
        mujoco.mj_setConst(fresh, mujoco.MjData(fresh))
        base._set_const()
        for name in dir(fresh):
            value = getattr(fresh, name)
            if isinstance(value, np.ndarray):
                np.testing.assert_array_equal(getattr(base.model, name), value, err_msg=name)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_step_measures_match_the_robot_model(env_id: str) -> None:
    """The env's per-step measures (MuJoCo's subtree CoM and velocity on the env's data) equal
    ``RobotModel``'s (its CoM Jacobian and minimal coordinates) on random rolling states."""
    env = gym.make(env_id, tray_attachment="free") if env_id in TRAY_IDS else gym.make(env_id)
    env.reset(seed=0)
    base = env.unwrapped
    robot = base.robot
    lay = robot.layout
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(-0.3, 0.3, lay.n_min)
        nu = rng.uniform(-1.0, 1.0, lay.n_min)
        qpos, qvel = robot.full_state(q, nu)
        full_qpos, full_qvel = base.data.qpos.copy(), base.data.qvel.copy()
        full_qpos[: lay.nq], full_qvel[: lay.nv] = qpos, qvel
        base.set_state(full_qpos, full_qvel)
        base._measure()
        info = base._info(fallen=False)
        robot.update(qpos, qvel, dynamics=False)
        for key, value in (
            ("theta", robot.theta),
            ("thetad", robot.thetad),
            ("x", q[0]),
            ("xd", nu[0]),
            ("axle_position", robot.axle_position),
        ):
            np.testing.assert_allclose(info[key], value, atol=1e-9, err_msg=key)
        if not lay.planar:
            np.testing.assert_allclose(info["psi"], q[1], atol=1e-9)
            np.testing.assert_allclose(info["psid"], nu[1], atol=1e-9)
