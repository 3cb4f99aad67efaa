"""A benchmark scenario: which env, with which task parameters, for how long."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

import wip_gym

DEFAULT_DURATION_S = 25.0  # the plan horizon (20 s) plus 5 s to settle


def resolve_env_id(name: str) -> str:
    """Accept ``wip_gym/PlanarTray-v0`` or the bare ``PlanarTray-v0``."""
    candidates = [name, f"wip_gym/{name}"]
    for candidate in candidates:
        if candidate in wip_gym.ENV_IDS:
            return candidate
    raise ValueError(f"unknown env {name!r}; valid: {sorted(wip_gym.ENV_IDS)}")


def parse_controllers(text: str) -> list[str]:
    """Comma-separated registry names; ``ValueError`` naming the valid ones."""
    from controllers.registry import controller_names

    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in controller_names()]
    if unknown or not names:
        raise ValueError(f"unknown controllers {unknown}; valid: {controller_names()}")
    if len(set(names)) != len(names):
        raise ValueError(f"--controllers lists a controller twice: {names}")
    return names


def check_task_flags(env_id: str, goal: list[float] | None, cup_friction: float | None) -> None:
    """The CLI's checks of ``--goal`` and ``--cup-friction`` (the env checks the rest)."""
    if goal is not None and len(goal) not in (1, 2):
        raise ValueError(f"--goal takes X or X Y, got {len(goal)} values")
    if cup_friction is not None and not (np.isfinite(cup_friction) and cup_friction > 0):
        raise ValueError(f"--cup-friction must be positive, got {cup_friction}")
    if cup_friction is not None and "Tray" not in env_id:
        raise ValueError(f"--cup-friction needs a tray task; {env_id} has no cup")


@dataclass(frozen=True)
class Push:
    """A force along the heading at the torso's CoM: ``NEWTONS@SECONDS[:DURATION]``."""

    force: float
    time: float
    duration: float = 0.1

    @classmethod
    def parse(cls, text: str) -> Push:
        try:
            force, _, rest = text.partition("@")
            when, _, duration = rest.partition(":")
            push = cls(float(force), float(when), float(duration) if duration else 0.1)
        except ValueError:
            raise ValueError(
                f"bad push {text!r}: expected NEWTONS@SECONDS[:DURATION], e.g. 80@2:0.2"
            ) from None
        if push.time < 0 or push.duration <= 0:
            raise ValueError(f"bad push {text!r}: time must be >= 0 and duration > 0")
        return push


@dataclass(frozen=True)
class Scenario:
    """Everything that defines an episode but the controller and the seed."""

    env_id: str
    goal: tuple[float, ...] | None = None
    push: Push | None = None
    payload_mass: float = 0.0
    payload_time: float = 0.0
    cup_friction: float | None = None
    duration: float = DEFAULT_DURATION_S
    model: str = "nominal"

    def __post_init__(self) -> None:
        object.__setattr__(self, "env_id", resolve_env_id(self.env_id))
        if self.duration <= 0:
            raise ValueError(f"duration must be positive, got {self.duration}")
        if self.goal is not None and len(self.goal) not in (1, 2):
            raise ValueError(f"goal takes X or X Y, got {self.goal}")
        if self.model not in ("nominal", "oracle"):
            raise ValueError(f"model must be nominal or oracle, got {self.model!r}")

    def env_kwargs(self) -> dict[str, Any]:
        kwargs: dict[str, Any] = {
            "payload_mass": self.payload_mass,
            "payload_time": self.payload_time,
        }
        if self.goal is not None:
            kwargs["goal"] = self.goal[0] if len(self.goal) == 1 else tuple(self.goal)
        if self.push is not None:
            kwargs.update(
                push_force=self.push.force,
                push_time=self.push.time,
                push_duration=self.push.duration,
            )
        if self.cup_friction is not None:
            kwargs["cup_friction"] = self.cup_friction
        return kwargs

    def make_env(self, **extra: Any) -> gym.Env:
        return gym.make(self.env_id, max_episode_steps=-1, **self.env_kwargs(), **extra)

    def describe(self) -> dict[str, Any]:
        """Every parameter, defaults included (read back from the env)."""
        env = self.make_env()
        base = env.unwrapped
        force, push_time, push_duration = base.push
        described = {
            "env": self.env_id,
            "goal": [float(v) for v in base.goal],
            "cup_friction": base.cup_friction,
            "payload_mass": self.payload_mass,
            "payload_time": self.payload_time,
            "push": {"force": force, "time": push_time, "duration": push_duration},
            "duration_s": self.duration,
            "control_dt_s": float(base.dt),
            "reset_noise_scale": base.reset_noise_scale,
            "wheel_torque_limit": base.scene_options.wheel_torque_limit,
            "model": self.model,
        }
        env.close()
        return described

    def replace(self, **changes: Any) -> Scenario:
        return dataclasses.replace(self, **changes)
