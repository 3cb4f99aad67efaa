"""The viewer (benchmarks/view.py, wip_gym/display.py, docs/videos.md §6) where it can be tested
without a display: the clear error instead of GLFW's abort, ``wip-bench view``'s arguments, the
states it shows live and replayed (through a stand-in for MuJoCo's viewer), and ``wip-bench
render``'s new files beside a run's videos."""

from __future__ import annotations

import argparse
import hashlib
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import pytest

from benchmarks import view
from benchmarks.cli import build_parser, main
from benchmarks.overrides import resolve_run
from benchmarks.rollout import rollout
from wip_gym.recording import EpisodeRecorder, Recording

ROOT = Path(__file__).resolve().parents[1]


def headless_environment() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def test_human_render_mode_without_a_display_raises_instead_of_aborting() -> None:
    code = (
        "import gymnasium as gym, numpy as np, wip_gym\n"
        "env = gym.make('wip_gym/WIP-v0', render_mode='human')\n"
        "env.reset(seed=0)\n"
        "env.step(np.zeros(2))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code],
        env=headless_environment(),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 1, (done.returncode, done.stderr[-2000:])  # GLFW's abort: 134
    assert "NoDisplayError: render_mode='human' opens a window and needs a display" in done.stderr
    assert "rgb_array" in done.stderr


def test_view_without_a_display_is_a_usage_error(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(SystemExit) as exit_info:
        main(["view", "--env", "Planar-v0", "--controller", "decoupled"])
    assert exit_info.value.code == 2
    assert "wip-bench view opens a window and needs a display" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--speed", "0"], "--speed must be positive"),
        (["--duration", "-1"], "--duration must be positive"),
        (["--controller", "nobody"], "unknown controllers"),
        (["--env", "Nowhere-v0"], "unknown env"),
        (["--set", "env.nothing=1"], "env.nothing"),
        (["--replay", "no/such/file.npz"], "no such recording"),
    ],
)
def test_view_checks_its_arguments_before_anything_runs(
    flags: list[str],
    message: str,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.setenv("DISPLAY", ":0")  # the arguments are checked before the display
    with pytest.raises(SystemExit) as exit_info:
        main(["view", *flags])
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err


def test_view_parses_its_arguments() -> None:
    args = build_parser().parse_args(
        ["view", "--env", "WIP-v0", "--controller", "decoupled", "--seed", "4", "--speed", "0.5"]
    )
    assert (args.command, args.env, args.controller, args.seed, args.speed) == (
        "view",
        "WIP-v0",
        "decoupled",
        4,
        0.5,
    )
    assert args.replay is None and args.overrides == [] and args.duration == 25.0


class FakeViewer:
    """Stands in for ``mujoco.viewer.launch_passive``'s handle: keeps the state at each sync;
    its window is 'closed' after ``close_after`` syncs."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, close_after: int) -> None:
        self.model, self.data, self.close_after = model, data, close_after
        self.states: list[tuple[float, np.ndarray, np.ndarray]] = []
        self.entered = self.exited = False

    def __enter__(self) -> FakeViewer:
        self.entered = True
        return self

    def __exit__(self, *exc: object) -> None:
        self.exited = True

    def is_running(self) -> bool:
        return len(self.states) < self.close_after

    def sync(self) -> None:
        self.states.append((float(self.data.time), self.data.qpos.copy(), self.data.qvel.copy()))


class FakeLauncher:
    def __init__(self, close_after: int = 10**9) -> None:
        self.close_after = close_after
        self.viewers: list[FakeViewer] = []

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData) -> FakeViewer:
        viewer = FakeViewer(model, data, self.close_after)
        self.viewers.append(viewer)
        return viewer


def view_args(*flags: str) -> argparse.Namespace:
    return build_parser().parse_args(["view", *flags])


def test_live_view_shows_the_rollouts_states(monkeypatch: pytest.MonkeyPatch) -> None:
    """The viewer is opened on the env's own model and data at the reset and synced every
    1/60 s of simulated time: the states it shows are the rollout's at those steps."""
    monkeypatch.setenv("DISPLAY", ":0")
    launcher = FakeLauncher()
    flags = ["--env", "Planar-v0", "--controller", "decoupled", "--seed", "2"]
    result = view.run(view_args(*flags, "--duration", "0.1", "--speed", "1e6"), launcher, False)
    assert not result["closed"] and result["metrics"]["steps"] == 100
    (viewer,) = launcher.viewers
    assert viewer.entered and viewer.exited
    every = round(1 / (view.VIEW_FPS * 0.001))  # 17 steps of 1 ms
    expected_steps = list(range(0, 101, every))
    assert len(viewer.states) == len(expected_steps) == result["syncs"]
    seen: dict[int, tuple[float, np.ndarray, np.ndarray]] = {}

    def keep(env: gym.Env, info: dict[str, Any], n: int) -> None:
        data = env.unwrapped.data
        seen[n] = (float(data.time), data.qpos.copy(), data.qvel.copy())

    spec = resolve_run("wip_gym/Planar-v0", ["decoupled"])
    rollout(
        "wip_gym/Planar-v0",
        spec.env_kwargs,
        "decoupled",
        spec.configs["decoupled"],
        2,
        0.1,
        on_step=keep,
    )
    for n, (t, qpos, qvel) in zip(expected_steps, viewer.states, strict=True):
        assert t == seen[n][0]
        np.testing.assert_array_equal(qpos, seen[n][1])
        np.testing.assert_array_equal(qvel, seen[n][2])


def test_closing_the_window_stops_the_episode(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DISPLAY", ":0")
    launcher = FakeLauncher(close_after=2)
    flags = ["--env", "WIP-v0", "--controller", "decoupled", "--duration", "5", "--speed", "1e6"]
    result = view.run(view_args(*flags), launcher, False)
    assert result["closed"] and result["syncs"] == 2 and launcher.viewers[0].exited


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short KrangTray-v0 episode under zero torques whose payload appears at 0.05 s,
    recorded at 100 fps."""
    env = gym.make("wip_gym/KrangTray-v0", payload_mass=1.0, payload_time=0.05)
    recorder = EpisodeRecorder(fps=100, label="zero")
    _, info = env.reset(seed=3)
    recorder.on_reset(env, info)
    zero = np.zeros(env.action_space.shape)
    for n in range(150):
        _, _, _, _, info = env.step(zero)
        recorder.on_step(env, info, n)
    env.close()
    return recorder.save(tmp_path_factory.mktemp("recording") / "recording_zero.npz")


def test_replay_sets_the_recorded_states(recording: Path) -> None:
    rec = Recording.load(recording)
    env = gym.make(rec.env_id, **rec.env_kwargs)
    base = env.unwrapped
    base.reset(seed=0)
    model, data = base.model, base.data
    payload = [g for g in range(model.ngeom) if model.body(model.geom_bodyid[g]).name == "payload"]
    shown = []
    for k in view.replay_states(rec, model, data):
        alpha = model.geom_rgba[payload, 3]
        assert (alpha == 0).all() != bool(rec.payload_visible[k])
        shown.append((data.time, data.qpos.copy(), data.qvel.copy()))
    assert len(shown) == rec.frames == 16 and not rec.payload_visible[0]
    np.testing.assert_array_equal([s[0] for s in shown], rec.time)
    np.testing.assert_array_equal(np.array([s[1] for s in shown]), rec.qpos)
    np.testing.assert_array_equal(np.array([s[2] for s in shown]), rec.qvel)
    env.close()


def test_view_replays_a_recording(recording: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DISPLAY", ":0")
    rec = Recording.load(recording)
    for target in (str(recording), str(recording.parent)):  # the file, or its run's directory
        launcher = FakeLauncher()
        result = view.run(view_args("--replay", target, "--speed", "1e6"), launcher, False)
        assert result == {"replayed": "zero", "frames": rec.frames}
        (viewer,) = launcher.viewers
        np.testing.assert_array_equal(np.array([s[1] for s in viewer.states]), rec.qpos)
        goal = viewer.model.site_pos[viewer.model.site("goal").id, :2]
        np.testing.assert_array_equal(goal, rec.goal)


def _digests(directory: Path) -> dict[str, str]:
    return {
        p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(directory.glob("*.mp4"))
    }


def test_render_writes_new_files_beside_the_runs_videos(tmp_path: Path) -> None:
    flags = ["--env", "Planar-v0", "--controllers", "decoupled", "--duration", "0.2"]
    main(["compare", "--out", str(tmp_path), *flags, "--video", "both", "--size", "64x48"])
    run_videos = _digests(tmp_path)
    assert set(run_videos) == {"video_decoupled.mp4", "video_grid.mp4"}
    for camera in ("tray", "follow"):  # another camera, and the run's own one
        main(["render", str(tmp_path), "--camera", camera, "--size", "64x48"])
        tag = f"{camera}-64x48-30fps"
        now = _digests(tmp_path)
        assert {f"video_decoupled.{tag}.mp4", f"video_grid.{tag}.mp4"} <= set(now)
        assert (tmp_path / f"video_grid.{tag}.json").exists()
        assert {k: now[k] for k in run_videos} == run_videos  # the run's videos untouched
