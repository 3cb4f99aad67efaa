"""One episode of ``wip-bench compare``: the rollout, with a video and progress reports.

``compare_episode`` is what compare's worker processes run; it is a top-level function with
picklable arguments (spawned processes), and reports simulated seconds through ``progress``
(a callable in-process, or a queue across processes).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from benchmarks.metrics import time_to_goal
from benchmarks.rollout import ProgressHook, rollout
from benchmarks.transitions import TransitionRecorder
from wip_gym.recording import DEFAULT_FPS, EpisodeRecorder

__all__ = ["RecordingHook", "compare_episode", "time_to_goal"]


class RecordingHook:
    """Adapts :class:`wip_gym.recording.EpisodeRecorder` to the rollout's ``on_step`` hook
    (index 0 is the state after ``reset``; index ``n`` the state after ``n`` steps). The
    recording is saved at the end and rendered afterwards, outside the control loop."""

    def __init__(self, recorder: EpisodeRecorder) -> None:
        self.recorder = recorder

    def __call__(self, env: gym.Env, info: dict[str, Any], step_index: int) -> None:
        if step_index == 0:
            self.recorder.on_reset(env, info)
        else:
            self.recorder.on_step(env, info, step_index - 1)


def compare_episode(
    task_index: int,
    env_id: str,
    env_kwargs: Mapping[str, Any],
    controller: str,
    config: Any,
    seed: int,
    duration: float,
    recording_path: str | None = None,
    fps: float | None = None,
    transitions_path: str | None = None,
    progress: Any = None,
) -> tuple[dict[str, Any], NDArray[np.float64]]:
    """One rollout; its metrics and per-step control times. With ``recording_path`` the
    episode is recorded at ``fps`` (default 30) for its video (rendered afterwards from the
    record, :mod:`wip_gym.recording`); with ``transitions_path`` its observations, actions,
    rewards, terminations and truncations are saved there (``benchmarks.transitions``).
    ``progress`` is None, a queue (``.put``) or a callable that receives ``(task_index,
    simulated_s)`` tuples."""
    recorder = None
    if recording_path is not None:
        recorder = EpisodeRecorder(
            DEFAULT_FPS if fps is None else fps,
            controller,
            env_id,
            dict(env_kwargs),
            meta={"seed": seed},
        )
    report: ProgressHook | None = None
    if progress is not None:
        send = progress.put if hasattr(progress, "put") else progress

        def report(simulated_s: float) -> None:
            send((task_index, simulated_s))

    transitions = TransitionRecorder() if transitions_path is not None else None
    episode = rollout(
        env_id,
        dict(env_kwargs),
        controller,
        config,
        seed,
        duration,
        on_step=None if recorder is None else RecordingHook(recorder),
        progress=report,
        on_transition=transitions,
    )
    if recorder is not None:
        recorder.save(recording_path)
    if transitions is not None:
        assert transitions_path is not None
        transitions.save(transitions_path, seed)
    return episode.metrics, episode.control_times
