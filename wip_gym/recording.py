"""Record an episode at the video rate, for rendering afterwards (``wip_gym.replay``).

Rendering in the control loop makes the video's cost part of the controller's timing. The
:class:`EpisodeRecorder` instead keeps, at the video rate, what a replay needs and cannot
recompute: the full ``qpos``/``qvel`` of the env's model (robot, tray, cup), the overlay's
values (contact forces give the friction use; the cup's loss; the payload's appearance; the
goal), and the resolved scenario (env id and keyword arguments) the model is rebuilt from.

A rollout calls ``on_reset(env, info)`` once after ``reset`` and ``on_step(env, info,
step_index)`` after every step (``step_index`` 0 for the first step), then ``save(path)``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from wip_gym.envs.base import wip_env

DEFAULT_FPS = 30.0
RECORDING_VERSION = 1
# make() arguments that choose how to render, not what happens: not part of the scenario
_RENDER_KWARGS = ("render_mode", "width", "height", "camera_name", "camera_id", "render_overlay")


def frame_interval(dt: float, fps: float) -> int:
    """Steps between two video frames: ``round(1 / (fps dt))``, at least 1."""
    if not (math.isfinite(dt) and math.isfinite(fps)) or dt <= 0 or fps <= 0:
        raise ValueError(f"dt and fps must be positive, got dt={dt}, fps={fps}")
    return max(1, int(round(1.0 / (fps * dt))))


def scenario_of(env: gym.Env) -> tuple[str, dict[str, Any]]:
    """The env id and the keyword arguments it was made with (render arguments left out)."""
    spec = env.spec if env.spec is not None else env.unwrapped.spec
    if spec is None:
        raise ValueError("the env was not made with gymnasium.make: pass env_id and env_kwargs")
    kwargs = {k: v for k, v in spec.kwargs.items() if k not in _RENDER_KWARGS}
    return spec.id, kwargs


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


@dataclass
class Recording:
    """An episode at the video rate (arrays: one row per frame).

    Attributes:
        env_id, env_kwargs: the scenario (``gymnasium.make(env_id, **env_kwargs)``).
        label: the panel's name (the controller).
        fps: the recording's frame rate; frame ``k`` is at ``time[k]``.
        dt: the env's step (s).
        steps: the episode's number of steps (its length is ``steps * dt``).
        goal: the goal ``(X, Y)``.
        time, qpos, qvel: the state of the env's whole model at each frame.
        goal_distance, tray_tilt_deg, friction_use: the overlay's values (NaN: no tray).
        cup_on_tray, payload_visible: per frame.
        cup_lost_at: the step time at which the cup left the tray (NaN: never), at the
            control rate, not rounded to a frame.
        meta: what the recorder was given to keep (e.g. the seed).
    """

    env_id: str
    env_kwargs: dict[str, Any]
    label: str
    fps: float
    dt: float
    steps: int
    goal: NDArray[np.float64]
    time: NDArray[np.float64]
    qpos: NDArray[np.float64]
    qvel: NDArray[np.float64]
    goal_distance: NDArray[np.float64]
    tray_tilt_deg: NDArray[np.float64]
    friction_use: NDArray[np.float64]
    cup_on_tray: NDArray[np.bool_]
    payload_visible: NDArray[np.bool_]
    cup_lost_at: float = math.nan
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def frames(self) -> int:
        return len(self.time)

    @property
    def has_tray(self) -> bool:
        return bool(np.isfinite(self.tray_tilt_deg).any())

    def save(self, path: str | Path) -> Path:
        """Write an ``.npz`` (the scenario and labels as JSON inside it)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        header = {
            "version": RECORDING_VERSION,
            "env_id": self.env_id,
            "env_kwargs": _jsonable(self.env_kwargs),
            "label": self.label,
            "fps": self.fps,
            "dt": self.dt,
            "steps": self.steps,
            "cup_lost_at": None if math.isnan(self.cup_lost_at) else self.cup_lost_at,
            "meta": _jsonable(self.meta),
        }
        np.savez_compressed(
            path,
            header=np.array(json.dumps(header)),
            goal=self.goal,
            time=self.time,
            qpos=self.qpos,
            qvel=self.qvel,
            goal_distance=self.goal_distance,
            tray_tilt_deg=self.tray_tilt_deg,
            friction_use=self.friction_use,
            cup_on_tray=self.cup_on_tray,
            payload_visible=self.payload_visible,
        )
        return path

    @classmethod
    def load(cls, path: str | Path) -> Recording:
        with np.load(path, allow_pickle=False) as data:
            header = json.loads(str(data["header"]))
            if header.get("version") != RECORDING_VERSION:
                raise ValueError(
                    f"{path}: recording version {header.get('version')!r}, "
                    f"this wip-gym reads {RECORDING_VERSION}"
                )
            lost = header["cup_lost_at"]
            return cls(
                env_id=header["env_id"],
                env_kwargs=header["env_kwargs"],
                label=header["label"],
                fps=float(header["fps"]),
                dt=float(header["dt"]),
                steps=int(header["steps"]),
                goal=data["goal"],
                time=data["time"],
                qpos=data["qpos"],
                qvel=data["qvel"],
                goal_distance=data["goal_distance"],
                tray_tilt_deg=data["tray_tilt_deg"],
                friction_use=data["friction_use"],
                cup_on_tray=data["cup_on_tray"],
                payload_visible=data["payload_visible"],
                cup_lost_at=math.nan if lost is None else float(lost),
                meta=header.get("meta", {}),
            )


class EpisodeRecorder:
    """Keeps an episode's frames at ``fps``: frame 0 at reset, then frame ``j`` at the first
    step whose time reaches ``j / fps`` (so the frames keep the video's clock; at 1 ms steps
    and 30 fps they are 33 or 34 steps apart).

    Args:
        fps: the video rate.
        label: the panel's name (the controller).
        env_id, env_kwargs: the scenario; read from ``env.spec`` when omitted.
        meta: anything JSON-able kept with the recording (e.g. the seed).
    """

    def __init__(
        self,
        fps: float = DEFAULT_FPS,
        label: str = "",
        env_id: str | None = None,
        env_kwargs: dict[str, Any] | None = None,
        meta: dict[str, Any] | None = None,
    ) -> None:
        if not math.isfinite(fps) or fps <= 0:
            raise ValueError(f"fps must be positive, got {fps}")
        self.fps = float(fps)
        self.label = label
        self.meta = dict(meta or {})
        self._scenario = None if env_id is None else (env_id, dict(env_kwargs or {}))
        self._rows: dict[str, list[Any]] = {}
        self._every = 0
        self._dt = 0.0
        self._steps = 0
        self._goal = np.zeros(2)
        self._cup_lost_at = math.nan

    def on_reset(self, env: gym.Env, info: dict[str, Any]) -> None:
        """Start (or restart) the recording at the reset state: frame 0."""
        base = wip_env(env)
        if self._scenario is None:
            self._scenario = scenario_of(env)
        self._dt = float(base.dt)
        self._every = frame_interval(self._dt, self.fps)  # > 0 marks "started"
        self._rows = {key: [] for key in _ROW_KEYS}
        self._steps = 0
        self._goal = np.asarray(base.goal, dtype=np.float64)
        self._cup_lost_at = math.nan
        self._append(base, info)

    def on_step(self, env: gym.Env, info: dict[str, Any], step_index: int) -> None:
        """After step ``step_index`` (0-based): note a lost cup; keep a frame at the rate."""
        if self._every == 0:
            raise RuntimeError("EpisodeRecorder.on_step before on_reset")
        base = wip_env(env)
        self._steps = step_index + 1
        # a free tray off the hand ends the episode like a lost cup: the overlay marks both
        lost = not info.get("cup_on_tray", True) or not info.get("tray_on_hand", True)
        if lost and math.isnan(self._cup_lost_at):
            self._cup_lost_at = float(base.data.time)
        if self._frame_of(step_index + 1) > self._frame_of(step_index):
            self._append(base, info)

    def _frame_of(self, steps: int) -> int:
        return int(math.floor(steps * self._dt * self.fps + 1e-9))

    def _append(self, base: Any, info: dict[str, Any]) -> None:
        rows, data = self._rows, base.data
        rows["time"].append(float(data.time))
        rows["qpos"].append(data.qpos.copy())
        rows["qvel"].append(data.qvel.copy())
        rows["goal_distance"].append(float(info["goal_distance"]))
        rows["tray_tilt_deg"].append(float(info.get("tray_tilt_deg", math.nan)))
        rows["friction_use"].append(float(info.get("cup_friction_use", math.nan)))
        rows["cup_on_tray"].append(bool(info.get("cup_on_tray", True)))
        rows["payload_visible"].append(bool(getattr(base, "payload_visible", False)))

    def recording(self) -> Recording:
        """What was recorded so far."""
        if self._scenario is None or not self._rows.get("time"):
            raise RuntimeError("nothing recorded: call on_reset first")
        env_id, env_kwargs = self._scenario
        rows = {k: np.asarray(v) for k, v in self._rows.items()}
        return Recording(
            env_id=env_id,
            env_kwargs=env_kwargs,
            label=self.label,
            fps=self.fps,
            dt=self._dt,
            steps=self._steps,
            goal=self._goal,
            cup_lost_at=self._cup_lost_at,
            meta=self.meta,
            **rows,
        )

    def save(self, path: str | Path) -> Path:
        """Write the recording (``.npz``); returns the path."""
        return self.recording().save(path)


_ROW_KEYS = (
    "time",
    "qpos",
    "qvel",
    "goal_distance",
    "tray_tilt_deg",
    "friction_use",
    "cup_on_tray",
    "payload_visible",
)
