"""Offscreen rendering: framing, replay from a recording, the mp4 helpers, a clean exit."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import imageio.v2 as imageio
import mujoco
import numpy as np
import pytest

import wip_gym
from wip_gym.overlay import OverlayValues, bar_colour, draw_overlay
from wip_gym.recording import EpisodeRecorder, Recording
from wip_gym.replay import Replay, frame_count, parse_size
from wip_gym.video import frame_interval, record_episode

HIDDEN_GROUP = 5  # a geom group MjvOption does not draw by default


@pytest.mark.parametrize("env_id", list(wip_gym.ENV_IDS))
def test_rgb_frame_is_not_blank(env_id: str) -> None:
    env = gym.make(env_id, render_mode="rgb_array", width=160, height=112)
    env.reset(seed=0)
    frame = env.render()
    env.close()
    assert frame.shape == (112, 160, 3) and frame.dtype == np.uint8
    assert frame.std() > 10  # a scene, not one flat colour


def _robot_silhouette(
    env_id: str, width: int = 240, height: int = 160, yaw: float = 0.0
) -> np.ndarray:
    """Pixels that change when the robot's geoms (its whole tree from ``base``, tray included)
    are hidden by moving them to a geom group the renderer does not draw: found without the
    camera code. ``yaw``: the robot turned by that angle (rad) about the vertical first."""
    env = gym.make(env_id, render_mode="rgb_array", width=width, height=height)
    env.reset(seed=0)
    model, data = env.unwrapped.model, env.unwrapped.data
    if yaw:
        quat = data.qpos[3:7].copy()
        turn = np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
        mujoco.mju_mulQuat(data.qpos[3:7], turn, quat)
        mujoco.mj_forward(model, data)
    with_robot = env.render().astype(int)
    root = model.body_rootid[model.body("base").id]
    mine = model.body_rootid[model.geom_bodyid] == root
    model.geom_group[mine] = HIDDEN_GROUP
    without_robot = env.render().astype(int)
    env.close()
    return np.abs(with_robot - without_robot).max(axis=2) > 30


def _extent(mask: np.ndarray, axis: int) -> tuple[int, int]:
    present = np.flatnonzero(mask.any(axis=axis))
    assert len(present) > 0, "the robot is not in the frame"
    return int(present[0]), int(present[-1])


@pytest.mark.parametrize("env_id", list(wip_gym.ENV_IDS))
def test_default_camera_frames_the_robot(env_id: str) -> None:
    """At reset the robot is >= 55 % of the frame high, its middle in the middle third."""
    mask = _robot_silhouette(env_id)
    top, bottom = _extent(mask, 1)
    left, right = _extent(mask, 0)
    height, width = mask.shape
    fraction_high = (bottom - top + 1) / height
    middle = 0.5 * (left + right) / width
    assert fraction_high >= 0.55, f"robot {fraction_high:.0%} of the frame high"
    assert top > 0, "the robot's top is cut off"
    assert 0.35 <= middle <= 0.65, f"robot's middle at {middle:.0%} of the width"


def test_follow_camera_turns_with_the_heading() -> None:
    """The robot turned by 90 deg is still seen from its side: its silhouette keeps its width
    (seen from the front, the WIP's wheels and body are half as wide again) and its place."""
    straight = _robot_silhouette("wip_gym/WIP-v0")
    turned = _robot_silhouette("wip_gym/WIP-v0", yaw=np.pi / 2)
    left, right = _extent(straight, 0)
    turned_left, turned_right = _extent(turned, 0)
    assert abs((turned_right - turned_left) - (right - left)) <= 0.05 * (right - left) + 2
    assert abs((turned_left + turned_right) - (left + right)) <= 0.05 * straight.shape[1]


def test_replayed_frame_equals_live_frame(tmp_path: Path) -> None:
    """A state recorded in the loop and drawn from the file looks exactly as the live env drew
    it (payload appearing mid-episode included)."""
    kwargs = {"payload_mass": 1.0, "payload_time": 0.1}
    env = gym.make("wip_gym/KrangTray-v0", render_mode="rgb_array", width=160, height=112, **kwargs)
    recorder = EpisodeRecorder(fps=30, label="zero", meta={"seed": 3})
    _, info = env.reset(seed=3)
    recorder.on_reset(env, info)
    live = [env.render()]
    zero = np.zeros(env.action_space.shape)
    for n in range(200):
        _, _, _, _, info = env.step(zero)
        before = len(recorder._rows["time"])
        recorder.on_step(env, info, n)
        if len(recorder._rows["time"]) > before:
            live.append(env.render())
    env.close()
    path = recorder.save(tmp_path / "run.npz")
    recording = Recording.load(path)
    assert recording.env_id == "wip_gym/KrangTray-v0"
    assert recording.env_kwargs == kwargs and recording.meta == {"seed": 3}
    assert recording.frames == len(live) == frame_count(recording, 30) == 7
    assert not recording.payload_visible[0] and recording.payload_visible[-1]
    with Replay(recording, 160, 112, overlay=False) as replay:
        for k in (0, 3, len(live) - 1):
            np.testing.assert_array_equal(replay.frame(k), live[k])


def test_overlay_marks_slip_and_cup_loss() -> None:
    frame = np.full((160, 240, 3), 128, dtype=np.uint8)
    calm = draw_overlay(frame, OverlayValues(1.0, 0.5, 2.0, 0.3, label="unified"))
    slip = draw_overlay(frame, OverlayValues(1.0, 0.5, 2.0, 1.05, label="unified"))
    lost = draw_overlay(frame, OverlayValues(1.0, 0.5, 2.0, 0.3, True, 0.8, label="unified"))
    assert bar_colour(1.0) == (220, 30, 30) and bar_colour(0.3)[0] < 200
    red = (slip[..., 0] > 200) & (slip[..., 1] < 60) & (slip[..., 2] < 60)
    assert red[-20:].sum() > 50 and not ((calm[..., 0] > 200) & (calm[..., 1] < 60)).any()
    banner = (lost[..., 0] > 180) & (lost[..., 1] < 40) & (lost[..., 2] < 40)
    assert banner[:30].sum() > 100  # the red "CUP LOST" banner at the top
    assert not np.array_equal(calm[:20, :60], frame[:20, :60])  # the label is drawn


def test_render_overlay_is_off_unless_asked() -> None:
    frames = []
    for overlay in (False, True):
        env = gym.make(
            "wip_gym/PlanarTray-v0",
            render_mode="rgb_array",
            width=240,
            height=160,
            render_overlay=overlay,
        )
        env.reset(seed=0)
        frames.append(env.render().astype(int))
        env.close()
    plain, drawn = frames
    changed = np.abs(plain - drawn).max(axis=2) > 30
    assert changed[:30, :80].mean() > 0.2  # the text box at the top left
    assert changed[-12:].mean() > 0.2  # the friction bar at the bottom
    assert not changed[60:120, 90:150].any()  # the robot itself is not covered


def test_frame_interval_decimates_to_30_fps() -> None:
    assert frame_interval(0.001, 30) == 33
    assert frame_interval(0.01, 30) == 3
    with pytest.raises(ValueError):
        frame_interval(0.0, 30)


def test_parse_size_wants_even_sizes() -> None:
    assert parse_size("480x320") == (480, 320)
    for bad in ("481x320", "480", "axb", "0x0"):
        with pytest.raises(ValueError):
            parse_size(bad)


def test_unknown_camera_names_the_valid_ones() -> None:
    env = gym.make("wip_gym/PlanarTray-v0", render_mode="rgb_array", camera_name="nope")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="follow"):
        env.render()
    env.close()


def test_record_episode_writes_a_readable_mp4(tmp_path: Path) -> None:
    env = gym.make("wip_gym/KrangTray-v0", width=160, height=112)
    path = tmp_path / "episode.mp4"
    result = record_episode(env, path, seconds=0.2, seed=0, camera="tray")
    env.close()
    assert result["steps"] == 200
    assert result["frames"] == 1 + 6  # 0.2 s at 30 fps
    frames = imageio.mimread(path)
    assert len(frames) == result["frames"] and frames[0].shape == (112, 160, 3)
    assert Recording.load(path.with_suffix(".npz")).steps == 200


def test_no_traceback_at_exit_without_close() -> None:
    """An env and a renderer left open: the interpreter exits quietly."""
    code = (
        "import gymnasium as gym, wip_gym\n"
        "from wip_gym.renderer import FrameRenderer\n"
        "env = gym.make('wip_gym/KrangTray-v0', render_mode='rgb_array', width=64, height=48)\n"
        "env.reset(seed=0); env.render()\n"
        "r = FrameRenderer(env.unwrapped.model, 64, 48, camera='tray')\n"
        "r.render(env.unwrapped.data)\n"
        "print('rendered')\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False
    )
    assert done.returncode == 0 and "rendered" in done.stdout
    assert "Traceback" not in done.stderr and "Exception ignored" not in done.stderr, done.stderr


def test_replay_draws_a_still_robot_once(tmp_path: Path) -> None:
    """Frames whose state moved less than the still tolerance reuse the drawn scene (only the
    overlay changes) and look like the exact frames; a state that moved is drawn again."""
    env = gym.make("wip_gym/Planar-v0")
    recorder = EpisodeRecorder(fps=30)
    _, info = env.reset(seed=0)
    recorder.on_reset(env, info)
    for n in range(300):
        _, _, _, _, info = env.step(np.zeros(env.action_space.shape))
        recorder.on_step(env, info, n)
    env.close()
    recording = recorder.recording()
    rng = np.random.default_rng(0)
    still = recording.qpos[1] + rng.uniform(-5e-5, 5e-5, recording.qpos[1:6].shape)
    recording.qpos[1:6] = still  # frames 1-5: "standing still"; 6-9 fall on
    with Replay(recording, 160, 112) as replay:
        drawn = []
        render_qpos = replay._renderer.render_qpos
        replay._renderer.render_qpos = lambda q, *a: drawn.append(q) or render_qpos(q, *a)
        frames = list(replay.frames())
        assert len(drawn) == len(frames) - 4  # frames 2-5 reuse frame 1's scene
        exact = Replay(recording, 160, 112, still_tolerance=0.0)
        for k in (2, 5, 8):
            assert np.abs(frames[k].astype(int) - exact.frame(k).astype(int)).mean() < 0.5
        exact.close()
        assert not np.array_equal(frames[2], frames[3])  # the overlay's time moves on
