"""``wip-bench compare --video grid`` and ``wip-bench render``: the controllers side by side."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import gymnasium as gym
import imageio.v2 as imageio
import numpy as np
import pytest

from benchmarks.cli import main
from wip_gym.recording import EpisodeRecorder
from wip_gym.replay import grid_layout, read_frames, render_grid

PANEL = (160, 112)
FPS = 20


def _frames(path: Path) -> list[np.ndarray]:
    return list(read_frames(path))


def _panels(frame: np.ndarray, columns: int) -> list[np.ndarray]:
    width, height = PANEL
    rows = frame.shape[0] // height
    return [
        frame[r * height : (r + 1) * height, c * width : (c + 1) * width]
        for r in range(rows)
        for c in range(columns)
    ]


def _label_box(panel: np.ndarray) -> np.ndarray:
    """The label's line (top left of a panel): white text on the darkened box."""
    return panel[2:12, 2:70]


def test_compare_writes_a_labelled_grid_and_render_redraws_it(tmp_path: Path) -> None:
    controllers = ["decoupled", "decoupled-mpc"]
    size = f"{PANEL[0]}x{PANEL[1]}"
    flags = ["--env", "PlanarTray-v0", "--controllers", ",".join(controllers)]
    flags += ["--duration", "0.5", "--video", "both", "--size", size, "--fps", str(FPS)]
    main(["compare", "--out", str(tmp_path), *flags])
    grid = _frames(tmp_path / "video_grid.mp4")
    assert len(grid) == 1 + int(0.5 * FPS)  # the episode's frames at the chosen rate
    rows, columns = grid_layout(len(controllers))
    assert grid[0].shape == (rows * PANEL[1], columns * PANEL[0], 3)
    layout = json.loads((tmp_path / "video_grid.json").read_text())
    assert layout["panels"] == controllers and layout["frames"] == len(grid)
    labels = [_label_box(p) for p in _panels(grid[0], columns)[: len(controllers)]]
    for label in labels:  # white text in each panel's label box
        assert ((label > 200).all(axis=2)).sum() > 10
    # the names differ, so the label boxes do (beyond the codec's noise)
    assert np.abs(labels[0].astype(int) - labels[1].astype(int)).max() > 100
    for name in controllers:
        assert len(_frames(tmp_path / f"video_{name}.mp4")) == len(grid)

    again = tmp_path / "tray"
    main(
        [
            "render",
            str(tmp_path),
            "--camera",
            "tray",
            "--video",
            "grid",
            "--size",
            size,
            "--out",
            str(again),
        ]
    )
    redrawn = _frames(again / f"video_grid.tray-{size}-{FPS}fps.mp4")  # named by its view
    assert len(redrawn) == len(grid) and redrawn[0].shape == grid[0].shape
    assert np.abs(redrawn[0].astype(int) - grid[0].astype(int)).mean() > 10  # another view

    still = tmp_path / "still.png"
    main(["render", str(tmp_path), "--still", str(still), "--size", size])
    image = imageio.imread(still)
    assert image.shape == grid[0].shape  # the grid's first frame, lossless
    assert np.abs(image.astype(int) - grid[0].astype(int)).mean() < 3  # (the codec's loss)


def test_an_episode_that_ends_early_holds_its_last_frame(tmp_path: Path) -> None:
    env = gym.make("wip_gym/Planar-v0")
    recorder = EpisodeRecorder(fps=FPS, label="long")
    _, info = env.reset(seed=0)
    recorder.on_reset(env, info)
    zero = np.zeros(env.action_space.shape)
    for n in range(600):  # 0.6 s without control: the robot tips over
        _, _, _, _, info = env.step(zero)
        recorder.on_step(env, info, n)
    env.close()
    long = recorder.recording()
    keep = 5  # frames: 0.2 s at 20 fps
    short = dataclasses.replace(
        long,
        label="short",
        steps=200,
        **{
            f: getattr(long, f)[:keep]
            for f in (
                "time",
                "qpos",
                "qvel",
                "goal_distance",
                "tray_tilt_deg",
                "friction_use",
                "cup_on_tray",
                "payload_visible",
            )
        },
    )
    path = tmp_path / "grid.mp4"
    layout = render_grid([long, short, long], path, size=PANEL, fps=FPS)
    frames = _frames(path)
    assert layout["rows"] == 2 and layout["columns"] == 2
    assert len(frames) == layout["frames"] == 1 + int(0.6 * FPS)
    after = [_panels(f, 2) for f in frames[keep:]]
    moving = [p[0].astype(int) for p in after]
    held = [p[1].astype(int) for p in after]
    assert np.abs(moving[-1] - moving[0]).mean() > 2  # the long episode goes on
    assert max(np.abs(h - held[0]).mean() for h in held) < 1.0  # the short one holds
    assert frames[0][PANEL[1] :, PANEL[0] :].max() == 0  # the fourth cell is empty


@pytest.mark.parametrize(
    "flags",
    [["--size", "161x112"], ["--camera", "nope"], ["--video", "mosaic"], ["--fps", "0"]],
)
def test_compare_rejects_bad_video_flags(tmp_path: Path, flags: list[str]) -> None:
    with pytest.raises(SystemExit) as error:
        main(["compare", "--out", str(tmp_path), "--controllers", "decoupled", "--video", *flags])
    assert error.value.code == 2
    assert not (tmp_path / "summary.json").exists()  # refused before any episode


def test_render_needs_recordings(tmp_path: Path) -> None:
    with pytest.raises(SystemExit) as error:
        main(["render", str(tmp_path)])
    assert error.value.code == 2
