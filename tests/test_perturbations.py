"""The perturbation env arguments (docs/realism.md), each held to an independent fact: a delay
against the same env fed the shifted actions, the noise's sample statistics against its
documented standard deviations, the slope's holding torque against statics, a bump's lift
against its height, the lag's step response against ``1 - exp(-t / tau)``, the model errors
against their ranges; and every argument at its default changes nothing."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import wip_gym  # noqa: F401
from controllers.registry import make_policy
from wip_gym.envs.base import WHEEL_RESET_DEPTH
from wip_gym.envs.perturbations import Perturbations
from wip_gym.envs.sensors import SensorModel

PLANAR, KRANG = "wip_gym/Planar-v0", "wip_gym/Krang-v0"
#: every perturbation argument at its default value (off)
OFF: dict[str, Any] = {
    "sensor_noise": 0.0,
    "obs_delay_steps": 0,
    "obs_delay_jitter_steps": 0,
    "action_delay_steps": 0,
    "action_delay_jitter_steps": 0,
    "actuator_lag_s": 0.0,
    "joint_lag_s": None,
    "torque_noise": 0.0,
    "com_offset": 0.0,
    "inertia_randomization": 0.0,
    "joint_damping": 0.0,
    "joint_friction": 0.0,
    "floor_friction": 1.0,
    "floor_slope_deg": 0.0,
    "bump_height": 0.0,
    "bump_spacing": 1.0,
    "bump_width": 0.1,
}


def _make(env_id: str, **kwargs: Any) -> Any:
    return gym.make(env_id, max_episode_steps=100_000, **kwargs)


def _actions(env: Any, n: int, seed: int, scale: float = 0.05) -> list[np.ndarray]:
    """``n`` random torques, ``scale`` of each actuator's limit."""
    rng = np.random.default_rng(seed)
    high = env.action_space.high.astype(np.float64)
    return [scale * high * rng.uniform(-1.0, 1.0, len(high)) for _ in range(n)]


def _state(env: Any) -> np.ndarray:
    d = env.unwrapped.data
    return np.concatenate([d.qpos, d.qvel, d.act])


# ------------------------------------------------------------------------------ off is today
def test_the_dataclass_defaults_are_the_env_defaults() -> None:
    settings = Perturbations()
    floor = settings.floor
    assert {
        **{k: getattr(settings, k) for k in OFF if hasattr(settings, k)},
        "floor_slope_deg": floor.slope_deg,
        "bump_height": floor.bump_height,
        "bump_spacing": floor.bump_spacing,
        "bump_width": floor.bump_width,
    } == OFF
    assert not settings.active


@pytest.mark.parametrize("env_id", [PLANAR, "wip_gym/KrangTray-v0"])
def test_every_argument_at_its_default_is_todays_env_to_the_bit(env_id: str) -> None:
    today, off = _make(env_id), _make(env_id, **OFF)
    base = off.unwrapped
    assert not (base._perturb_model or base._perturb_action or base._perturb_observation)
    for name in ("body_mass", "body_inertia", "body_ipos", "dof_damping", "dof_frictionloss"):
        np.testing.assert_array_equal(
            getattr(base.model, name), getattr(today.unwrapped.model, name)
        )
    assert base.model.na == 0 and base.model.ngeom == today.unwrapped.model.ngeom
    obs_a, _ = today.reset(seed=4)
    obs_b, _ = off.reset(seed=4)
    for a in _actions(today, 200, 1):
        obs_a, r_a, *_ = today.step(a)
        obs_b, r_b, *_ = off.step(a)
        assert r_a == r_b
        for key in obs_a:
            np.testing.assert_array_equal(obs_a[key], obs_b[key])
    # and the env's own stream was drawn from alike
    assert today.unwrapped.np_random.random() == base.np_random.random()


def test_the_same_seed_gives_the_same_true_state_with_noise_on_or_off() -> None:
    clean, noisy = _make(KRANG), _make(KRANG, sensor_noise=3.0, torque_noise=0.0)
    obs_c, info_c = clean.reset(seed=11)
    obs_n, info_n = noisy.reset(seed=11)
    np.testing.assert_array_equal(_state(clean), _state(noisy))
    assert not np.array_equal(obs_c["qpos"], obs_n["qpos"])
    for a in _actions(clean, 100, 2):
        clean.step(a)
        noisy.step(a)
    np.testing.assert_array_equal(_state(clean), _state(noisy))


# ------------------------------------------------------------------------------------ delays
@pytest.mark.parametrize("env_id", [PLANAR, KRANG])
def test_a_delayed_action_acts_exactly_that_many_steps_later(env_id: str) -> None:
    """The delay line starts with zero torque: the delayed env is the undelayed one fed
    ``d`` zero actions first, state for state, to the bit."""
    d = 3
    delayed, reference = _make(env_id, action_delay_steps=d), _make(env_id)
    delayed.reset(seed=2)
    reference.reset(seed=2)
    actions = _actions(delayed, 60, 3)
    zero = np.zeros(delayed.action_space.shape)
    for k, a in enumerate(actions):
        delayed.step(a)
        reference.step(zero if k < d else actions[k - d])
        np.testing.assert_array_equal(_state(delayed), _state(reference), err_msg=f"step {k}")
        applied = delayed.unwrapped.data.ctrl
        np.testing.assert_array_equal(applied, zero if k < d else actions[k - d])


def test_the_delay_line_keeps_its_own_copy_of_each_action() -> None:
    """A policy may write each action into the same array: the line holds what was given."""
    env = _make(PLANAR, action_delay_steps=2)
    env.reset(seed=1)
    actions = _actions(env, 10, 6)
    buffer = np.zeros(env.action_space.shape)
    for k, a in enumerate(actions):
        buffer[:] = a
        env.step(buffer)
        if k >= 2:
            np.testing.assert_array_equal(env.unwrapped.data.ctrl, actions[k - 2])


def test_action_jitter_draws_each_steps_delay_from_its_range() -> None:
    env = _make(PLANAR, action_delay_steps=1, action_delay_jitter_steps=2)
    env.reset(seed=5)
    actions = _actions(env, 300, 4)
    seen = set()
    for k, a in enumerate(actions):
        env.step(a)
        delay = env.unwrapped.perturber._action_line.last_delay
        seen.add(delay)
        assert 1 <= delay <= 3
        expected = actions[k - delay] if k - delay >= 0 else np.zeros_like(a)
        np.testing.assert_array_equal(env.unwrapped.data.ctrl, expected)
    assert seen == {1, 2, 3}


@pytest.mark.parametrize("env_id", [PLANAR, "wip_gym/KrangTray-v0"])
def test_a_delayed_observation_is_the_one_of_that_many_steps_before(env_id: str) -> None:
    d = 4
    delayed, reference = _make(env_id, obs_delay_steps=d), _make(env_id)
    obs_d, _ = delayed.reset(seed=6)
    obs_r, _ = reference.reset(seed=6)
    history = [obs_r]
    for key in obs_r:
        np.testing.assert_array_equal(obs_d[key], obs_r[key])
    for k, a in enumerate(_actions(delayed, 40, 5), start=1):
        obs_d, *_ = delayed.step(a)
        obs_r, *_ = reference.step(a)
        history.append(obs_r)
        due = history[max(k - d, 0)]  # until the first delayed one arrives: the reset's
        for key in obs_r:
            np.testing.assert_array_equal(obs_d[key], due[key], err_msg=f"{key} at step {k}")
    np.testing.assert_array_equal(_state(delayed), _state(reference))


# ------------------------------------------------------------------------------------ sensors
def _heading_frame_error(q_obs: np.ndarray, q_true: np.ndarray) -> np.ndarray:
    """The rotation from the true to the observed base attitude, as (roll, pitch, yaw) about
    the heading frame's axes (rad)."""
    inverse, delta = np.zeros(4), np.zeros(4)
    mujoco.mju_negQuat(inverse, q_true)
    mujoco.mju_mulQuat(delta, q_obs, inverse)
    vector = np.zeros(3)
    mujoco.mju_quat2Vel(vector, delta, 1.0)
    rotation = np.zeros(9)
    mujoco.mju_quat2Mat(rotation, q_true)
    psi = math.atan2(-rotation[1], rotation[4])
    c, s = math.cos(psi), math.sin(psi)
    return np.array([c * vector[0] + s * vector[1], -s * vector[0] + c * vector[1], vector[2]])


def _within(sample_std: float, expected: float, n: int) -> None:
    """A sample standard deviation of ``n`` draws against its expected value, within five of
    its own standard errors (``expected / sqrt(2 (n - 1))`` for normal draws)."""
    assert abs(sample_std - expected) < 5 * expected / math.sqrt(2 * (n - 1)), (
        sample_std,
        expected,
        n,
    )


def test_the_reset_errors_have_the_documented_spread_over_resets() -> None:
    """At each reset: attitude and gyro errors are the episode's bias plus one white sample;
    the encoders' errors are uniform within half a step."""
    figures = SensorModel().scaled(1.0, 1e-3)
    env = _make(KRANG, sensor_noise=1.0)
    base = env.unwrapped
    lay = base.robot.layout
    encoders = [*lay.wheel_qpos, *lay.body_qpos]
    attitude, gyro, wheel, joint = [], [], [], []
    n = 400
    for seed in range(n):
        obs, _ = env.reset(seed=seed)
        d = base.data
        attitude.append(_heading_frame_error(obs["qpos"][3:7], d.qpos[3:7]))
        gyro.append(obs["qvel"][3:6] - d.qvel[3:6])
        error = obs["qpos"][encoders] - d.qpos[encoders]
        wheel.extend(error[:2])
        joint.extend(error[2:])
    attitude_ = np.array(attitude)
    for axis in (0, 1):  # roll, pitch
        _within(
            float(attitude_[:, axis].std(ddof=1)),
            math.hypot(figures.attitude_bias, figures.attitude_noise),
            n,
        )
    _within(float(attitude_[:, 2].std(ddof=1)), figures.attitude_noise, n)  # yaw: no drift yet
    gyro_ = np.array(gyro)
    for axis in range(3):
        _within(
            float(gyro_[:, axis].std(ddof=1)), math.hypot(figures.gyro_bias, figures.gyro_noise), n
        )
    for errors, step in (
        (np.array(wheel), figures.wheel_step),
        (np.array(joint), figures.joint_step),
    ):
        assert np.abs(errors).max() <= step / 2 * (1 + 1e-9)
        # a uniform's sample variance has a relative standard error sqrt(0.8 / n)
        m = len(errors)
        assert abs(errors.std() / (step / math.sqrt(12)) - 1) < 5 * 0.5 * math.sqrt(0.8 / m)
    assert figures.wheel_step == pytest.approx(2 * math.pi / 60_000)


@pytest.mark.parametrize("env_id", [PLANAR, KRANG])
def test_within_an_episode_the_white_noise_has_its_documented_spread(env_id: str) -> None:
    """Per sample: attitude white noise about the episode's bias, the gyro's about its bias;
    encoder rates are the readings' difference over the step; the heading drifts by the
    integrated gyro bias; planar odometry carries the wheels' and the IMU's errors."""
    figures = SensorModel().scaled(1.0, 1e-3)
    noisy = _make(env_id, sensor_noise=1.0)
    base = noisy.unwrapped
    lay = base.robot.layout
    planar = lay.planar
    wheels = list(lay.wheel_qpos)
    pitch_white, gyro_white = [], []
    for episode in range(4):
        obs, _ = noisy.reset(seed=100 + episode)
        previous = base.data.qpos[wheels].copy()
        previous_readings = obs["qpos"][wheels]
        pitch, gyro, yaw, predicted_yaw = [], [], [], []
        drift = 0.0
        for _ in range(300):
            obs, *_ = noisy.step(np.zeros(noisy.action_space.shape))
            d = base.data
            true_wheels = d.qpos[wheels]
            rates = obs["qvel"][list(lay.wheel_dof)]
            readings = obs["qpos"][wheels]
            # the rate is the readings' backward difference over the step, so it is off the
            # true angles' difference by at most one encoder step per step
            np.testing.assert_allclose(
                rates, (readings - previous_readings) / base.dt, rtol=1e-12, atol=1e-9
            )
            difference = (true_wheels - previous) / base.dt
            assert np.all(np.abs(rates - difference) <= figures.wheel_step / base.dt * (1 + 1e-9))
            previous, previous_readings = true_wheels.copy(), readings
            if planar:
                pitch.append(obs["qpos"][2] - d.qpos[2])
                gyro.append([obs["qvel"][2] - d.qvel[2]])
                wheel_error = float(np.mean(readings - true_wheels))
                np.testing.assert_allclose(
                    obs["qpos"][0] - d.qpos[0],
                    lay.wheel_radius * (wheel_error + pitch[-1]),
                    rtol=0,
                    atol=1e-14,
                )
            else:
                error = _heading_frame_error(obs["qpos"][3:7], d.qpos[3:7])
                pitch.append(error[1])
                yaw.append(error[2])
                gyro.append(obs["qvel"][3:6] - d.qvel[3:6])
                rotation = d.xmat[lay.base_body].reshape(3, 3)
                predicted_yaw.append(rotation[2])
        pitch_ = np.array(pitch)
        gyro_ = np.array(gyro)
        pitch_white.extend(pitch_ - pitch_.mean())
        gyro_white.extend((gyro_ - gyro_.mean(axis=0)).ravel())
        if not planar:
            bias = gyro_.mean(axis=0)  # the gyro's bias, estimated from its errors
            for row, world_rate in enumerate(predicted_yaw):
                drift += float(world_rate @ bias) * base.dt
                predicted_yaw[row] = drift
            # the heading's error: the integrated bias, within five of the white noise's
            # standard deviations and of the bias estimate's own error (300 samples per axis,
            # over at most 0.3 s)
            residual = np.array(yaw) - np.array(predicted_yaw)
            estimate = math.sqrt(3.0) * figures.gyro_noise / math.sqrt(300) * 0.3
            assert np.abs(residual).max() < 5 * (figures.attitude_noise + estimate)
    n = len(pitch_white)
    _within(float(np.std(pitch_white)), figures.attitude_noise, n)
    _within(float(np.std(gyro_white)), figures.gyro_noise, len(gyro_white))
    assert figures.gyro_noise == pytest.approx(4.9e-5 * math.sqrt(500.0))


def test_the_sensor_stream_is_its_own() -> None:
    """The same seed draws the same errors; another seed other ones; the env's own stream is
    untouched (the reset noise is the noiseless env's)."""
    a, b = _make(PLANAR, sensor_noise=1.0), _make(PLANAR, sensor_noise=1.0)
    obs_a, _ = a.reset(seed=9)
    obs_b, _ = b.reset(seed=9)
    np.testing.assert_array_equal(obs_a["qpos"], obs_b["qpos"])
    obs_c, _ = b.reset(seed=10)
    assert not np.array_equal(obs_a["qpos"], obs_c["qpos"])
    # an unseeded reset continues the stream: another draw than the seeded one
    obs_e, _ = a.reset()
    assert not np.array_equal(obs_a["qpos"], obs_e["qpos"])
    obs_d, _ = a.reset(seed=9)
    np.testing.assert_array_equal(obs_a["qpos"], obs_d["qpos"])
    # a generator set by the user (no seed known to the env): the streams follow its own seed
    # sequence, so two envs given equal generators draw alike
    for env in (a, b):
        env.unwrapped.np_random = np.random.default_rng(21)
    obs_f, _ = a.reset()
    obs_g, _ = b.reset()
    np.testing.assert_array_equal(obs_f["qpos"], obs_g["qpos"])


# ------------------------------------------------------------------------------ actuator lag
def test_the_lag_step_response_is_first_order_per_group() -> None:
    """A constant action from the reset: the torque each actuator applies over the k-th
    physics step is ``u (1 - exp(-k h / tau))``, ``tau`` the wheels' or the joints' own."""
    tau_wheels, tau_joints = 0.005, 0.002
    env = _make(PLANAR, actuator_lag_s=tau_wheels, joint_lag_s=tau_joints)
    env.reset(seed=0)
    base = env.unwrapped
    lay = base.robot.layout
    u = 0.1 * env.action_space.high.astype(np.float64)
    taus = np.full(len(u), tau_joints)
    taus[list(lay.wheel_actuators)] = tau_wheels
    h = float(base.model.opt.timestep)
    for k in range(1, 30):
        env.step(u)
        expected = u * (1.0 - np.exp(-k * h / taus))
        np.testing.assert_allclose(base.data.actuator_force, expected, rtol=1e-12, atol=1e-12)
        # the joints feel it: MuJoCo's generalised actuator force on each actuated dof
        dofs = [*lay.wheel_dof, *lay.body_dof]
        actuators = [*lay.wheel_actuators, *lay.joint_actuators]
        np.testing.assert_allclose(
            base.data.qfrc_actuator[dofs], expected[actuators], rtol=1e-12, atol=1e-12
        )
    env.reset(seed=0)  # the lag starts from zero torque at each reset
    np.testing.assert_array_equal(base.data.act, 0.0)


# ------------------------------------------------------------------------------ torque noise
def test_torque_noise_has_its_documented_spread() -> None:
    sigma = 0.01
    env = _make(KRANG, torque_noise=sigma)
    env.reset(seed=3)
    base = env.unwrapped
    limit = np.abs(env.action_space.high.astype(np.float64))
    u = np.zeros(len(limit))
    samples = []
    for _ in range(400):
        env.step(u)
        samples.append((base.data.ctrl - u) / limit)
    samples_ = np.array(samples).ravel()
    _within(float(samples_.std()), sigma, len(samples_))
    assert abs(samples_.mean()) < 5 * sigma / math.sqrt(len(samples_))


# ------------------------------------------------------------------------------- model error
MODEL_ERROR = {
    "com_offset": 0.02,
    "inertia_randomization": 0.1,
    "joint_damping": 0.3,
    "joint_friction": 0.2,
    "floor_friction": (0.4, 1.0),
}


def _model_arrays(env: Any) -> dict[str, np.ndarray]:
    m = env.unwrapped.model
    return {
        name: getattr(m, name).copy()
        for name in (
            "body_ipos",
            "body_inertia",
            "dof_damping",
            "dof_frictionloss",
            "geom_friction",
        )
    }


def test_model_errors_stay_in_their_ranges_and_follow_the_seed() -> None:
    nominal_env = _make("wip_gym/KrangTray-v0")
    nominal_env.reset(seed=0)
    nominal = _model_arrays(nominal_env)
    env = _make("wip_gym/KrangTray-v0", **MODEL_ERROR)
    base = env.unwrapped
    lay = base.robot.layout
    payload = base.model.body("payload").id
    bodies = [b for b in base._robot_bodies if b != payload]
    moved = [b for b in bodies if b not in lay.wheel_bodies]
    dofs = [*lay.wheel_dof, *lay.body_dof]
    wheels = [base.model.geom(n).id for n in ("wheel_left", "wheel_right")]
    draws = []
    for seed in range(20):
        env.reset(seed=seed)
        now = _model_arrays(env)
        draws.append(now)
        offset = now["body_ipos"] - nominal["body_ipos"]
        assert np.abs(offset[moved]).max() <= 0.02 and np.abs(offset[moved]).max() > 0.01
        np.testing.assert_array_equal(offset[[b for b in range(len(offset)) if b not in moved]], 0)
        massive = nominal["body_inertia"][bodies] > 0
        ratio = now["body_inertia"][bodies][massive] / nominal["body_inertia"][bodies][massive]
        assert ratio.min() >= 0.9 and ratio.max() <= 1.1
        added = now["dof_damping"][dofs] - nominal["dof_damping"][dofs]
        assert added.min() >= 0 and added.max() <= 0.3
        friction = now["dof_frictionloss"][dofs] - nominal["dof_frictionloss"][dofs]
        assert friction.min() >= 0 and friction.max() <= 0.2
        mu = now["geom_friction"][wheels, 0]
        assert mu[0] == mu[1] and 0.4 <= mu[0] <= 1.0
        # the rest of the model is as built
        others = [d for d in range(base.model.nv) if d not in dofs]
        np.testing.assert_array_equal(now["dof_damping"][others], nominal["dof_damping"][others])
    mus = [d["geom_friction"][wheels[0], 0] for d in draws]
    assert max(mus) - min(mus) > 0.3  # the range is drawn from, not one value
    env.reset(seed=7)
    again = _model_arrays(env)
    for name, value in again.items():
        np.testing.assert_array_equal(value, draws[7][name])
    assert not np.array_equal(again["body_ipos"], draws[8]["body_ipos"])


def test_model_errors_leave_the_reset_noise_alone() -> None:
    """The reset noise comes from the env's stream, which the model errors do not draw from:
    the body joints start where the nominal env's do."""
    clean, erred = _make(KRANG), _make(KRANG, **MODEL_ERROR)
    clean.reset(seed=3)
    erred.reset(seed=3)
    joints = list(clean.unwrapped.robot.layout.body_qpos)
    np.testing.assert_array_equal(
        clean.unwrapped.data.qpos[joints], erred.unwrapped.data.qpos[joints]
    )


# ------------------------------------------------------------------------------------- floor
@pytest.mark.parametrize("env_id", [PLANAR, "wip_gym/KrangTray-v0"])
@pytest.mark.parametrize("slope", [-8.0, 6.0])
def test_the_reset_puts_the_wheels_on_the_slope(env_id: str, slope: float) -> None:
    tray = {"tray_attachment": "free"} if "Tray" in env_id else {}
    env = _make(env_id, floor_slope_deg=slope, **tray)
    env.reset(seed=1)
    base = env.unwrapped
    m, d = base.model, base.data
    floor = m.geom("floor").id
    # the reset sets the wheels WHEEL_RESET_DEPTH (vertically) into the floor, so that the
    # floor carries the robot from the first step: along the slope's normal, that times cos
    depth = WHEEL_RESET_DEPTH * math.cos(math.radians(slope))
    for name in ("wheel_left", "wheel_right"):
        distance = mujoco.mj_geomDistance(m, d, m.geom(name).id, floor, 0.1, None)
        assert abs(distance + depth) < 1e-12, (name, distance)
    normal = d.geom_xmat[floor].reshape(3, 3)[:, 2]
    np.testing.assert_allclose(
        normal, [-math.sin(math.radians(slope)), 0, math.cos(math.radians(slope))], atol=1e-15
    )


def test_standing_still_on_a_slope_takes_the_torque_statics_predicts() -> None:
    """Held still on a slope by a controller that does not know it (``decoupled``, Krang
    2014's state feedback, which comes to rest at an offset), the wheels' torques add up to
    ``M g r sin(alpha)``: the whole robot's weight along the slope, carried by the wheels'
    friction, at the wheel radius."""
    slope = 5.0
    env = _make(PLANAR, floor_slope_deg=slope, goal=0.0)
    obs, info = env.reset(seed=0)
    base = env.unwrapped
    lay = base.robot.layout
    policy = make_policy("decoupled", env)
    policy.reset(obs, info)
    torques = []
    steps = round(15.0 / base.dt)
    for _ in range(steps):
        action = policy(obs)
        obs, _, terminated, _, _ = env.step(action)
        assert not terminated
        torques.append(action[list(lay.wheel_actuators)].sum())
    m = base.model
    mass = float(m.body_subtreemass[lay.base_body])
    gravity = -float(m.opt.gravity[2])
    expected = mass * gravity * lay.wheel_radius * math.sin(math.radians(slope))
    held = float(np.mean(torques[-round(3.0 / base.dt) :]))
    assert np.abs(base.data.qvel).max() < 1e-3  # at rest
    assert abs(held / expected - 1) < 1e-3, (held, expected)


def test_a_bump_lifts_the_wheel_by_its_height() -> None:
    """Driven onto a bump (``decoupled`` to a goal on its top) the axle comes to rest its
    height above where it rests on the flat floor, and never rose higher on the way."""
    height = 0.02
    bumpy = {"bump_height": height, "bump_spacing": 1.0, "bump_width": 0.5}
    heights = {}
    for name, kwargs in (("flat", {}), ("bump", bumpy)):
        env = _make(PLANAR, goal=1.0, **kwargs)
        obs, info = env.reset(seed=0)
        policy = make_policy("decoupled", env)
        policy.reset(obs, info)
        axle = []
        for _ in range(round(8.0 / env.unwrapped.dt)):
            obs, _, terminated, _, info = env.step(policy(obs))
            assert not terminated
            axle.append(env.unwrapped.data.qpos[1])  # root_z: the axle's height
        assert abs(info["x"] - 1.0) < 0.1  # at rest on the goal: on the bump's top
        heights[name] = np.array(axle)
    lift = heights["bump"][-1] - heights["flat"][-1]
    assert abs(lift - height) < 1e-6, lift
    assert heights["bump"].max() - heights["flat"][-1] < height + 1e-4


def test_bumps_meet_the_wheels_only() -> None:
    env = _make(PLANAR, bump_height=0.03, bump_spacing=0.8)
    m = env.unwrapped.model
    bumps = [g for g in range(m.ngeom) if (m.geom(g).name or "").startswith("bump")]
    assert bumps
    wheels = {m.geom(n).id for n in ("wheel_left", "wheel_right")}

    def meet(a: int, b: int) -> bool:
        return bool(
            (m.geom_contype[a] & m.geom_conaffinity[b])
            or (m.geom_contype[b] & m.geom_conaffinity[a])
        )

    for g in range(m.ngeom):
        if g in bumps or m.geom_bodyid[g] == 0:
            continue
        assert meet(g, bumps[0]) == (g in wheels), m.geom(g).name


def test_bad_values_are_refused_with_the_arguments_name() -> None:
    for kwargs, match in (
        ({"sensor_noise": -1.0}, "sensor_noise"),
        ({"obs_delay_steps": 1.5}, "obs_delay_steps"),
        ({"action_delay_steps": -1}, "action_delay_steps"),
        ({"actuator_lag_s": float("nan")}, "actuator_lag_s"),
        ({"inertia_randomization": 1.0}, "inertia_randomization"),
        ({"floor_friction": (1.0, 0.5)}, "floor_friction"),
        ({"floor_friction": 0.0}, "floor_friction"),
        ({"floor_slope_deg": 45.0}, "floor_slope_deg"),
        ({"bump_height": 0.02, "bump_width": 1.0, "bump_spacing": 1.0}, "bump_width"),
        ({"bump_height": 0.05, "bump_width": 0.1, "bump_spacing": 0.15}, "bump_spacing"),
    ):
        with pytest.raises(ValueError, match=match):
            gym.make(PLANAR, **kwargs)
