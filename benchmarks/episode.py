"""One episode of ``wip-bench compare``: the rollout, with a video and progress reports.

``compare_episode`` is what compare's worker processes run; it is a top-level function with
picklable arguments (spawned processes), and reports simulated seconds through ``progress``
(a callable in-process, or a queue across processes).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from benchmarks.metrics import time_to_goal
from benchmarks.rollout import ProgressHook, rollout
from wip_gym.video import open_video

VIDEO_FPS = 30.0

__all__ = ["VideoRecorder", "compare_episode", "time_to_goal"]


class VideoRecorder:
    """An ``on_step`` hook writing every ``1 / VIDEO_FPS`` s of the episode to an mp4."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._writer: Any = None
        self._every = 1

    def __call__(self, env: gym.Env, info: dict[str, Any], step_index: int) -> None:
        if step_index == 0:
            self._every = max(1, int(round(1.0 / (VIDEO_FPS * env.unwrapped.dt))))
            self._writer = open_video(self.path, VIDEO_FPS, env.render())
        elif step_index % self._every == 0:
            self._writer.append_data(env.render())

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None


def compare_episode(
    task_index: int,
    env_id: str,
    env_kwargs: Mapping[str, Any],
    controller: str,
    config: Any,
    seed: int,
    duration: float,
    video_path: str | None = None,
    video_size: tuple[int, int] = (480, 320),
    progress: Any = None,
) -> tuple[dict[str, Any], NDArray[np.float64]]:
    """One rollout; its metrics and per-step control times. ``progress`` is None, a queue
    (``.put``) or a callable that receives ``(task_index, simulated_s)`` tuples."""
    kwargs = dict(env_kwargs)
    recorder = None
    if video_path is not None:
        width, height = video_size
        kwargs.update(render_mode="rgb_array", width=width, height=height)
        recorder = VideoRecorder(video_path)
    report: ProgressHook | None = None
    if progress is not None:
        send = progress.put if hasattr(progress, "put") else progress

        def report(simulated_s: float) -> None:
            send((task_index, simulated_s))

    try:
        episode = rollout(
            env_id, kwargs, controller, config, seed, duration, on_step=recorder, progress=report
        )
    finally:
        if recorder is not None:
            recorder.close()
    return episode.metrics, episode.control_times
