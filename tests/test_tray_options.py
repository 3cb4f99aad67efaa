"""The tray envs' tray options: ``tray_attachment`` (welded | free), ``tray_rim``,
``tray_friction``; the free tray's supports, reset placement, rest, loss and nominal model."""

from __future__ import annotations

import pickle

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import wip_gym  # noqa: F401
from controllers.policy import controller_model
from wip_gym.scene import (
    AUTHORS_TRAY_RIM,
    CUP_FEET,
    TRAY_MASS,
    SceneOptions,
    build_model,
    tray_hand_geoms,
    tray_support_geoms,
)

TRAY_IDS = ["wip_gym/PlanarTray-v0", "wip_gym/KrangTray-v0"]
REST_TIME = 1.0  # s


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"tray_attachment": "glued"}, "tray_attachment must be one of \\['welded', 'free'\\]"),
        ({"tray_rim": -0.001}, "tray_rim"),
        ({"tray_rim": float("nan")}, "tray_rim"),
        ({"tray_friction": -0.1}, "tray_friction"),
        ({"tray_friction": float("inf")}, "tray_friction"),
    ],
)
def test_bad_tray_arguments_raise(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        gym.make("wip_gym/KrangTray-v0", **kwargs)


def test_tray_arguments_need_a_tray() -> None:
    with pytest.raises(ValueError, match="need a tray"):
        gym.make("wip_gym/Planar-v0", tray_attachment="free")


@pytest.mark.parametrize("env_id", TRAY_IDS)
def test_arguments_read_back(env_id: str) -> None:
    env = gym.make(env_id, tray_attachment="free", tray_rim=AUTHORS_TRAY_RIM, tray_friction=0.4)
    base = env.unwrapped
    assert (base.tray_attachment, base.tray_rim, base.tray_friction) == ("free", 0.005, 0.4)
    options = base.scene_options
    assert (options.tray_attachment, options.tray_rim, options.tray_friction) == (
        "free",
        0.005,
        0.4,
    )
    args = base.arguments
    assert args["tray_attachment"] == "free" and args["tray_friction"] == 0.4
    # every argument in effect is read back, and rebuilding from them gives the same model
    again = gym.make(env_id, **args).unwrapped
    assert again.arguments == args
    assert again.model.nq == base.model.nq and again.model.npair == base.model.npair
    default = gym.make(env_id).unwrapped.arguments
    assert (default["tray_attachment"], default["tray_rim"], default["tray_friction"]) == (
        "welded",
        0.0,
        0.3,
    )


@pytest.mark.parametrize("robot", ["planar7", "krang"])
@pytest.mark.parametrize("attachment", ["welded", "free"])
def test_tray_mass_rim_and_pairs(robot: str, attachment: str) -> None:
    m = build_model(
        SceneOptions(
            robot, tray=True, cup=True, tray_attachment=attachment, tray_rim=AUTHORS_TRAY_RIM
        )
    )
    tray = m.body("tray").id
    assert m.body_mass[tray] == pytest.approx(TRAY_MASS)
    rims = [g for g in range(m.ngeom) if m.geom(g).name.startswith("tray_rim")]
    assert len(rims) == 4
    assert all(m.geom_size[g][2] == pytest.approx(AUTHORS_TRAY_RIM / 2) for g in rims)
    pairs = {
        frozenset((m.geom(m.pair_geom1[p]).name, m.geom(m.pair_geom2[p]).name))
        for p in range(m.npair)
    }
    feet = [m.geom(g).name for g in range(m.ngeom) if m.geom(g).name.startswith("cup_foot")]
    assert len(feet) == CUP_FEET
    # the feet stand on the plate; the rim meets the cup's cylinder (wip_gym.scene.add_cup)
    cup_pairs = {p for p in pairs if p & {"cup", *feet}}
    assert cup_pairs == {frozenset(("tray", foot)) for foot in feet} | {
        frozenset((m.geom(g).name, "cup")) for g in rims
    }
    supports = {frozenset(("tray", s)) for s in tray_support_geoms(robot)}
    assert supports <= pairs if attachment == "free" else not supports & pairs
    hand = {
        frozenset((t, h))
        for t in ["tray", *(m.geom(g).name for g in rims)]
        for h in tray_hand_geoms(robot)
    }
    assert hand <= pairs if attachment == "free" else not hand & pairs
    free_joint = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "tray")
    assert (free_joint >= 0) == (attachment == "free")


def test_tray_friction_is_the_support_pairs_value() -> None:
    m = build_model(SceneOptions("krang", tray=True, tray_attachment="free", tray_friction=0.45))
    for name in tray_support_geoms("krang"):
        p = m.pair(f"tray_{name}")
        assert p.friction[0] == p.friction[1] == 0.45


@pytest.mark.parametrize("env_id", TRAY_IDS)
@pytest.mark.parametrize("attachment", ["welded", "free"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_tray_and_cup_start_exactly_in_contact(env_id: str, attachment: str, seed: int) -> None:
    """From the noisy reset: the cup 1 micron into the plate (a contact exactly at 0 is not
    active yet); a free tray resting on its supports (touching them, and still: with the robot
    held still it moves less than 0.05 mm in the first 50 ms)."""
    env = gym.make(env_id, tray_attachment=attachment, tray_rim=AUTHORS_TRAY_RIM)
    _, info = env.reset(seed=seed)
    base = env.unwrapped
    m, d = base.model, base.data
    for geom in ("cup", "cup_foot0", "cup_foot2"):
        cup = mujoco.mj_geomDistance(m, d, m.geom("tray").id, m.geom(geom).id, 0.05, None)
        assert cup == pytest.approx(-1e-6, abs=1e-8), geom
    if attachment == "welded":
        return
    robot = env.unwrapped.scene_options.robot
    distances = [
        mujoco.mj_geomDistance(m, d, m.geom("tray").id, m.geom(name).id, 0.05, None)
        for name in tray_support_geoms(robot)
    ]
    assert -1e-3 < min(distances) < 0.0  # resting: in the soft contact, not gapped
    lay = base.robot.layout
    m.dof_armature[: lay.nv] = 1e6  # the robot held still (a test harness)
    held = d.qpos[: lay.nq].copy()
    d.qvel[:] = 0.0  # the tray and cup were given the hand's (noise) velocity: hand held still
    start, path = info["tray_offset"], 0.0
    for _ in range(50):
        d.qpos[: lay.nq] = held
        d.qvel[: lay.nv] = 0.0
        mujoco.mj_forward(m, d)
        d.qfrc_applied[: lay.nv] = d.qfrc_bias[: lay.nv]
        info = env.step(np.zeros(env.action_space.shape))[4]
        path += float(np.linalg.norm(info["tray_offset"] - start))
        start = info["tray_offset"]
    assert path < 5e-5, f"the tray moved {path * 1e3:.3f} mm"


@pytest.mark.parametrize("env_id", TRAY_IDS)
def test_free_tray_at_rest_stays_on_the_hand(env_id: str) -> None:
    """The robot held still at its reset (state restored and bias forces applied before each
    step): the free tray with its cup stays on the hand, within 1 mm of its rest place."""
    env = gym.make(env_id, tray_attachment="free", reset_noise_scale=0.0)
    _, info = env.reset(seed=0)
    base = env.unwrapped
    m, d = base.model, base.data
    lay = base.robot.layout
    held = d.qpos[: lay.nq].copy()
    assert info["tray_on_hand"] and np.abs(info["tray_offset"]).max() < 1e-5  # settled again
    for _ in range(round(REST_TIME / base.dt)):
        d.qpos[: lay.nq] = held
        d.qvel[: lay.nv] = 0.0
        mujoco.mj_forward(m, d)
        d.qfrc_applied[: lay.nv] = d.qfrc_bias[: lay.nv]
        _, _, terminated, _, info = env.step(np.zeros(env.action_space.shape))
        assert not terminated
    assert info["tray_on_hand"] and info["cup_on_tray"]
    assert np.abs(info["tray_offset"]).max() < 1e-3, info["tray_offset"]


@pytest.mark.parametrize("env_id", TRAY_IDS)
def test_tray_off_the_hand_ends_the_episode(env_id: str) -> None:
    env = gym.make(env_id, tray_attachment="free")
    env.reset(seed=0)
    base = env.unwrapped
    qpos, qvel = base.data.qpos.copy(), base.data.qvel.copy()
    for joint in ("tray", "cup"):  # both dropped 5 cm
        qpos[base.model.joint(joint).qposadr[0] + 2] -= 0.05
    base.set_state(qpos, qvel)
    _, reward, terminated, _, info = env.step(np.zeros(env.action_space.shape))
    assert not info["tray_on_hand"] and info["tray_offset"][2] < -0.04
    assert terminated and info["reward_cup_loss"] < 0


@pytest.mark.parametrize("env_id", TRAY_IDS)
def test_welded_tray_reports_no_tray_slip(env_id: str) -> None:
    env = gym.make(env_id)
    _, info = env.reset(seed=0)
    for _ in range(20):
        _, _, _, _, info = env.step(np.zeros(env.action_space.shape))
    assert info["tray_on_hand"] and not np.any(info["tray_offset"])


@pytest.mark.parametrize("env_id", TRAY_IDS)
def test_nominal_model_welds_the_free_tray(env_id: str) -> None:
    """A controller's nominal model welds a free tray where it rests on the hand (the env's
    ``tray_rest`` site), not level at the mount: the same bodies and masses as a welded tray,
    the tray's pose in its body the rest pose."""
    env = gym.make(env_id, tray_attachment="free", tray_rim=AUTHORS_TRAY_RIM)
    nominal = controller_model(env, "nominal")
    robot = env.unwrapped.scene_options.robot
    welded = build_model(SceneOptions(robot, tray=True, tray_rim=AUTHORS_TRAY_RIM))
    rest = env.unwrapped.model.site("tray_rest")
    at_rest = build_model(
        SceneOptions(
            robot,
            tray=True,
            tray_rim=AUTHORS_TRAY_RIM,
            tray_weld=(*rest.pos.tolist(), *rest.quat.tolist()),
        )
    )
    assert mujoco.mj_name2id(nominal, mujoco.mjtObj.mjOBJ_JOINT, "tray") < 0
    assert nominal.nq == welded.nq and nominal.nbody == welded.nbody
    np.testing.assert_array_equal(nominal.body_mass, welded.body_mass)
    np.testing.assert_array_equal(nominal.body_quat, at_rest.body_quat)
    np.testing.assert_array_equal(nominal.body_pos, at_rest.body_pos)
    tray = nominal.body("tray").id
    np.testing.assert_allclose(nominal.body_quat[tray], rest.quat, atol=1e-12)


@pytest.mark.parametrize("env_id", TRAY_IDS)
def test_pickle_and_vector_env_keep_the_tray_options(env_id: str) -> None:
    kwargs = {"tray_attachment": "free", "tray_rim": AUTHORS_TRAY_RIM, "tray_friction": 0.4}
    env = gym.make(env_id, **kwargs)
    again = pickle.loads(pickle.dumps(env.unwrapped))
    assert again.arguments == env.unwrapped.arguments
    vec = gym.make_vec(env_id, num_envs=2, vectorization_mode="sync", **kwargs)
    _, infos = vec.reset(seed=0)
    assert infos["tray_on_hand"].all()
    _, _, _, _, infos = vec.step(np.zeros(vec.action_space.shape))
    assert infos["tray_offset"].shape == (2, 3)
    vec.close()
