"""``wip_gym.wrappers`` (docs/learning.md §5, §6): the flat observation against MuJoCo's own
kinematics on random states, its bounded components bounded, the action scaling's round trip
and its clip counting or error, the dense reward's terms, the random goal's seeding, and
Gymnasium's checker on the wrapped envs."""

from __future__ import annotations

import math

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import wip_gym
from wip_gym.wrappers import (
    ANGULAR_SPEED_SCALE,
    CUP_REST_Z,
    GOAL_SCALE_M,
    LINEAR_SPEED_SCALE,
    DenseReward,
    DenseRewardConfig,
    NormalizedObservation,
    ObservationNormalizer,
    RandomGoal,
    ScaledAction,
    wrap_for_learning,
)

ENV_IDS = list(wip_gym.ENV_IDS)


def _random_state(env: gym.Env, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """A random state of the whole scene set in the env's data (random base pose and
    orientation, joints anywhere in their ranges, random velocities; the cup and a free tray
    anywhere near the hand), forwarded; the observation the env would give of it."""
    base = env.unwrapped
    m, d = base.model, base.data
    lay = base.robot.layout
    qpos = d.qpos.copy()
    for j in range(m.njnt):
        a = m.jnt_qposadr[j]
        kind = m.jnt_type[j]
        if kind == mujoco.mjtJoint.mjJNT_FREE:
            qpos[a : a + 3] += rng.uniform(-3, 3, 3) * np.array([1, 1, 0.05])
            quat = rng.standard_normal(4)
            qpos[a + 3 : a + 7] = quat / np.linalg.norm(quat)
        elif m.jnt_limited[j]:
            qpos[a] = rng.uniform(*m.jnt_range[j])
        else:
            qpos[a] = rng.uniform(-10, 10)
    qvel = rng.uniform(-3, 3, m.nv)
    d.qpos[:], d.qvel[:] = qpos, qvel
    mujoco.mj_forward(m, d)
    goal = rng.uniform(-4, 4, 2)
    if lay.planar:
        goal[1] = 0.0
    obs = {"qpos": qpos[: lay.nq], "qvel": qvel[: lay.nv], "goal": goal}
    if base.scene_options.tray:
        tray, cup = m.body("tray").id, m.body("cup").id
        position = d.xmat[tray].reshape(3, 3).T @ (d.xpos[cup] - d.xpos[tray])
        conj, quat = np.zeros(4), np.zeros(4)
        mujoco.mju_negQuat(conj, d.xquat[tray])
        mujoco.mju_mulQuat(quat, conj, d.xquat[cup])
        obs["cup_pose"] = np.concatenate([position, quat])
    return obs


def _reference(env: gym.Env, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Each block of the normalised observation from the data's kinematics (``mj_forward``'s
    body frames and ``mj_objectVelocity`` at the base frame's origin), by its definition."""
    base = env.unwrapped
    m, d = base.model, base.data
    lay = base.robot.layout
    body = lay.base_body
    R = d.xmat[body].reshape(3, 3)
    axle = d.xpos[body]  # the base's origin is the axle midpoint (assets/mjcf/README.md)
    # the heading: perpendicular to the wheel axle (the base's y axis) in the floor's plane
    psi = math.atan2(-R[0, 1], R[1, 1])
    heading = np.array([[math.cos(psi), -math.sin(psi)], [math.sin(psi), math.cos(psi)]])
    velocity = np.zeros(6)
    mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_XBODY, body, velocity, 0)
    angular_world, linear = velocity[:3], velocity[3:]
    ref: dict[str, np.ndarray] = {}
    gravity = R.T @ np.array([0.0, 0.0, -1.0])
    if lay.planar:
        ref["goal"] = np.array([obs["goal"][0] - axle[0]]) / GOAL_SCALE_M
        ref["gravity"] = gravity[[0, 2]]
        ref["velocity"] = linear[[0, 2]] / LINEAR_SPEED_SCALE
        ref["rate"] = np.array([angular_world[1]]) / ANGULAR_SPEED_SCALE
    else:
        ref["goal"] = heading.T @ (obs["goal"] - axle[:2]) / GOAL_SCALE_M
        ref["gravity"] = gravity
        v = np.concatenate([heading.T @ linear[:2], linear[2:]])
        ref["velocity"] = v / LINEAR_SPEED_SCALE
        ref["rate"] = R.T @ angular_world / ANGULAR_SPEED_SCALE
    wheels = [m.joint(name) for name in ("wheel_left", "wheel_right")]
    ref["wheel_speed"] = (
        np.array([d.qvel[j.dofadr[0]] for j in wheels]) * lay.wheel_radius / LINEAR_SPEED_SCALE
    )
    ref["wheel_angle"] = np.array([d.qpos[j.qposadr[0]] for j in wheels])
    joints = [j for j in range(m.njnt) if m.jnt_qposadr[j] in lay.body_qpos]
    ref["joint"] = np.array(
        [
            2 * (d.qpos[m.jnt_qposadr[j]] - m.jnt_range[j, 0]) / np.ptp(m.jnt_range[j]) - 1
            for j in joints
        ]
    )
    ref["joint_rate"] = np.array([d.qvel[m.jnt_dofadr[j]] for j in joints]) / ANGULAR_SPEED_SCALE
    if base.scene_options.tray:
        tray, cup = m.body("tray").id, m.body("cup").id
        T = d.xmat[tray].reshape(3, 3)
        place = T.T @ (d.xpos[cup] - d.xpos[tray]) - [0, 0, CUP_REST_Z]
        ref["cup"] = place / np.array([0.15, 0.10, 0.04])
        ref["cup_axis"] = T.T @ d.xmat[cup].reshape(3, 3)[:, 2]
    return ref


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_the_normalised_observation_is_its_definition_on_random_states(env_id: str) -> None:
    env = gym.make(env_id)
    env.reset(seed=0)
    normalizer = ObservationNormalizer.for_env(env, "sincos", np.float64)
    names = normalizer.names
    rng = np.random.default_rng(1)
    for _ in range(20):
        obs = _random_state(env, rng)
        out = normalizer(obs)
        ref = _reference(env, obs)
        assert out.dtype == np.float64 and out.shape == (len(names),)
        blocks = {
            "goal": [n.startswith("goal_") for n in names],
            "gravity": [n.startswith("gravity_") for n in names],
            "velocity": [n.startswith("velocity_") for n in names],
            "rate": [n.startswith("rate_") for n in names],
            "wheel_speed": [n.startswith("wheel_speed_") for n in names],
            "joint": [n.startswith("joint_") and "rate" not in n for n in names],
            "joint_rate": [n.startswith("joint_rate_") for n in names],
        }
        if "cup_pose" in obs:
            blocks["cup"] = [n in ("cup_x", "cup_y", "cup_z") for n in names]
            blocks["cup_axis"] = [n.startswith("cup_axis_") for n in names]
        for block, mask in blocks.items():
            np.testing.assert_allclose(out[mask], ref[block], atol=1e-9, err_msg=block)
        angles = ref["wheel_angle"]
        sincos = [np.sin(angles[0]), np.cos(angles[0]), np.sin(angles[1]), np.cos(angles[1])]
        np.testing.assert_allclose(
            out[[n.startswith(("sin_", "cos_")) for n in names]], sincos, atol=1e-12
        )
        bounded = normalizer.bounded
        # gravity (planar 2, else 3), the wheels' sine and cosine (4), the cup's axis (3)
        assert bounded.sum() == (2 if normalizer.layout.planar else 3) + 4 + 3 * normalizer.tray
        assert np.all(np.abs(out[bounded]) <= 1.0)
        assert normalizer.space().contains(out.astype(normalizer.space().dtype))
    env.close()


@pytest.mark.parametrize("env_id", ["wip_gym/WIP-v0", "wip_gym/Planar-v0"])
def test_the_relative_goal_agrees_with_the_envs_info_along_an_episode(env_id: str) -> None:
    env = NormalizedObservation(gym.make(env_id, frame_skip=5))
    names = env.normalizer.names
    obs, info = env.reset(seed=2)
    rng = np.random.default_rng(3)
    for _ in range(60):
        goal = obs[[n.startswith("goal_") for n in names]].astype(np.float64) * GOAL_SCALE_M
        # float32 output: its rounding
        assert np.linalg.norm(goal) == pytest.approx(info["goal_distance"], rel=1e-6, abs=1e-6)
        if "psi" in info:
            c, s = math.cos(info["psi"]), math.sin(info["psi"])
            dx, dy = np.array([2.0, 0.0]) - info["axle_position"][:2]
            np.testing.assert_allclose(goal, [c * dx + s * dy, -s * dx + c * dy], atol=1e-5)
        action = rng.uniform(-0.3, 0.3, env.action_space.shape) * env.action_space.high
        obs, _, terminated, _, info = env.step(action)
        assert obs.dtype == np.float32 and env.observation_space.contains(obs)
        if terminated:
            break


def test_a_bad_observation_or_option_raises() -> None:
    env = gym.make("wip_gym/Planar-v0")
    obs, _ = env.reset(seed=0)
    normalizer = ObservationNormalizer.for_env(env)
    with pytest.raises(ValueError, match="observation shapes"):
        normalizer({**obs, "qpos": obs["qpos"][:-1]})
    with pytest.raises(ValueError, match="wheel_angles"):
        ObservationNormalizer.for_env(env, "cos")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="dtype"):
        ObservationNormalizer.for_env(env, dtype=np.int32)
    krang = gym.make("wip_gym/WIP-v0")
    kobs, _ = krang.reset(seed=0)
    with pytest.raises(ValueError, match="not a rotation quaternion"):
        ObservationNormalizer.for_env(krang)({**kobs, "qpos": np.zeros_like(kobs["qpos"])})


# ------------------------------------------------------------------------------ actions
def test_the_action_scaling_round_trip_and_its_clip_count() -> None:
    env = ScaledAction(gym.make("wip_gym/Planar-v0"))
    base = env.unwrapped
    low, high = base.action_space.low.astype(float), base.action_space.high.astype(float)
    rng = np.random.default_rng(0)
    a = rng.uniform(-1, 1, env.action_space.shape)
    np.testing.assert_allclose(env.to_action(env.to_torque(a)), a, atol=1e-15)
    np.testing.assert_array_equal(env.to_torque(np.ones_like(a)), high)
    np.testing.assert_array_equal(env.to_torque(-np.ones_like(a)), low)
    _, info = env.reset(seed=0)
    assert info["action_clipped"] is False and info["action_clip_steps"] == 0
    inside = np.full(env.action_space.shape, 0.1)
    _, _, _, _, info = env.step(inside)
    np.testing.assert_allclose(base.data.ctrl, 0.1 * high)
    assert info["action_clipped"] is False and info["action_clip_steps"] == 0
    beyond = inside.copy()
    beyond[0], beyond[3] = 1.5, -7.0
    for n in (1, 2):
        _, _, _, _, info = env.step(beyond)
        assert info["action_clipped"] is True and info["action_clip_steps"] == n
        assert base.data.ctrl[0] == high[0] and base.data.ctrl[3] == low[3]
    _, _, _, _, info = env.step(inside)
    assert info["action_clipped"] is False and info["action_clip_steps"] == 2
    _, info = env.reset(seed=1)
    assert info["action_clip_steps"] == 0 and env.clip_steps == 0


def test_the_action_scaling_errors() -> None:
    strict = ScaledAction(gym.make("wip_gym/WIP-v0"), out_of_range="error")
    strict.reset(seed=0)
    with pytest.raises(ValueError, match=r"beyond \[-1, 1\] at \[1\]"):
        strict.step(np.array([0.5, 1.01]))
    strict.step(np.array([1.0, -1.0]))  # the bounds themselves are inside
    clipping = ScaledAction(gym.make("wip_gym/WIP-v0"))
    clipping.reset(seed=0)
    with pytest.raises(ValueError, match="NaN"):
        clipping.step(np.array([np.nan, 0.0]))
    with pytest.raises(ValueError, match="shape"):
        clipping.step(np.zeros(3))
    with pytest.raises(ValueError, match="out_of_range"):
        ScaledAction(gym.make("wip_gym/WIP-v0"), out_of_range="wrap")  # type: ignore[arg-type]


# ------------------------------------------------------------------------------- reward
@pytest.mark.parametrize("env_id", ["wip_gym/WIP-v0", "wip_gym/PlanarTray-v0"])
def test_the_dense_reward_is_the_sum_of_its_documented_terms(env_id: str) -> None:
    config = DenseRewardConfig(
        alive=1.5, goal=0.7, goal_scale_m=0.8, theta=3.0, stop_width_m=0.2, ctrl=0.2, fall=7.0
    )
    env = DenseReward(gym.make(env_id, frame_skip=10), config)
    dt = env.unwrapped.dt
    limit = env.unwrapped.action_space.high.astype(float)
    # a goal near the start: the stop term is not negligible
    planar = env.unwrapped.robot.layout.planar
    _, info = env.reset(seed=4, options={"goal": 0.05 if planar else (0.05, 0.1)})
    before = info["goal_distance"]
    near = 0
    rng = np.random.default_rng(5)
    ended = False
    for _ in range(300):
        torque = rng.uniform(-0.4, 0.4, limit.shape) * limit
        _, reward, terminated, _, info = env.step(torque)
        terms = {k: v for k, v in info.items() if k.startswith("dense_")}
        assert reward == pytest.approx(sum(terms.values()), abs=1e-12)
        d = info["goal_distance"]
        expected = {
            "dense_alive": 0.0 if info["fallen"] else 1.5 * dt,
            "dense_goal": 0.7 * math.exp(-d / 0.8) * dt,
            "dense_progress": before - d,
            "dense_theta": -3.0 * info["theta"] ** 2 * dt,
            # xd -+ psid b: the wheels' ground speeds when they roll without slipping
            "dense_speed_at_goal": -math.exp(-((d / 0.2) ** 2))
            * (info["xd"] ** 2 + (info.get("psid", 0.0) * 0.34) ** 2)
            * dt,
            "dense_ctrl": -0.2 * float(np.sum((torque / limit) ** 2)) * dt,
            "dense_fall": -7.0 if info["fallen"] else 0.0,
        }
        if "psid" in info:
            expected["dense_spin"] = -0.1 * info["psid"] ** 2 * dt
        if "ee_error" in info:
            expected["dense_posture"] = -((info["ee_error"] / 0.1) ** 2) * dt
        if "tray_tilt_deg" in info:
            expected["dense_tray_tilt"] = -((info["tray_tilt_deg"] / 10) ** 2) * dt
            expected["dense_friction"] = -(info["cup_friction_use"] ** 2) * dt
            lost = not (info["cup_on_tray"] and info["tray_on_hand"])
            expected["dense_cup_loss"] = -10.0 if lost and info["reward_cup_loss"] else 0.0
        assert terms == pytest.approx(expected, abs=1e-12)
        near += abs(terms["dense_speed_at_goal"]) > 1e-6
        assert info["env_reward"] == pytest.approx(
            sum(v for k, v in info.items() if k.startswith("reward_")), abs=1e-12
        )
        before = d
        if terminated:
            ended = True
            break
    # random torques: the robot fell or the cup went, and that step's penalty was checked too;
    # the stop term was checked where it counts
    assert near > 5
    assert ended and (info["dense_fall"] != 0.0 or info.get("dense_cup_loss", 0.0) != 0.0)


def test_the_dense_reward_needs_torques_and_a_valid_config() -> None:
    with pytest.raises(ValueError, match="reads torques"):
        DenseReward(ScaledAction(gym.make("wip_gym/WIP-v0")))
    with pytest.raises(ValueError, match="spin must be finite and >= 0"):
        DenseRewardConfig(spin=-1.0)
    with pytest.raises(ValueError, match="stop_width_m must be positive"):
        DenseRewardConfig(stop_width_m=0.0)


# --------------------------------------------------------------------------------- goals
def test_random_goals_are_seeded_bounded_and_new_at_each_autoreset() -> None:
    def goals(seed: int) -> list[np.ndarray]:
        env = RandomGoal(gym.make("wip_gym/WIP-v0"), (-3.0, 1.0), (3.0, 2.0))
        found = [env.reset(seed=seed)[0]["goal"]]
        found += [env.reset()[0]["goal"] for _ in range(5)]  # no seed: a vector env's autoreset
        return found

    first, again, other = goals(11), goals(11), goals(12)
    np.testing.assert_array_equal(np.array(first), np.array(again))
    assert not np.allclose(np.array(first), np.array(other))
    assert len({tuple(g) for g in first}) == len(first)
    for g in first:
        assert -3 <= g[0] <= 3 and 1 <= g[1] <= 2
    planar = RandomGoal(gym.make("wip_gym/Planar-v0"), -1.0, 4.0)
    goal = planar.reset(seed=0)[0]["goal"]
    assert -1 <= goal[0] <= 4 and goal[1] == 0.0
    with pytest.raises(ValueError, match="1 entries"):
        RandomGoal(gym.make("wip_gym/Planar-v0"), (0, 0), (1, 1))
    with pytest.raises(ValueError, match="low <= high"):
        RandomGoal(gym.make("wip_gym/WIP-v0"), (1, 0), (0, 1))


# ------------------------------------------------------------------------------ checkers
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gymnasiums_checker_passes_on_the_wrapped_envs(env_id: str) -> None:
    planar = env_id in ("wip_gym/Planar-v0", "wip_gym/PlanarTray-v0")
    env = wrap_for_learning(
        gym.make(env_id, frame_skip=10),
        goal_low=-2.0 if planar else (-2.0, -2.0),
        goal_high=3.0 if planar else (3.0, 2.0),
        wheel_angles="sincos",
    )
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs) and env.action_space.shape == (
        env.unwrapped.model.nu,
    )
    env.close()
