"""Offscreen rendering and the mp4 helper."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import imageio.v2 as imageio
import numpy as np
import pytest

import wip_gym
from wip_gym.video import frame_interval, record_episode


@pytest.mark.parametrize("env_id", list(wip_gym.ENV_IDS))
def test_rgb_frame_is_not_blank(env_id: str) -> None:
    env = gym.make(env_id, render_mode="rgb_array", width=160, height=112)
    env.reset(seed=0)
    frame = env.render()
    env.close()
    assert frame.shape == (112, 160, 3) and frame.dtype == np.uint8
    assert frame.std() > 10  # a scene, not one flat colour


def test_frame_interval_decimates_to_30_fps() -> None:
    assert frame_interval(0.001, 30) == 33
    assert frame_interval(0.01, 30) == 3
    with pytest.raises(ValueError):
        frame_interval(0.0, 30)


def test_record_episode_writes_a_readable_mp4(tmp_path: Path) -> None:
    env = gym.make("wip_gym/KrangTray-v0", render_mode="rgb_array", width=160, height=112)
    path = tmp_path / "episode.mp4"
    result = record_episode(env, path, seconds=0.2, seed=0)
    env.close()
    assert result["steps"] == 200
    assert result["frames"] == 1 + 200 // 33
    frames = imageio.mimread(path)
    assert len(frames) == result["frames"]
