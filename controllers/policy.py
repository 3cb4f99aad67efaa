"""The policy protocol every wip-gym controller follows (issue 3, DESIGN 7).

    policy = Controller.for_env(env, config=None)   # reads the task, builds the nominal model
    policy.reset(observation, info)                  # all slow work: linearisation, planning
    action = policy(observation)                     # one control step
    policy.diagnostics                               # dict of signals a person would plot

A policy reads only the observation. It keeps its own MuJoCo data (a ``RobotModel``), rebuilt
from ``qpos``/``qvel``, and never reads the env's simulator. ``for_env`` builds a **nominal**
mass model: the robot with its tray, no cup, no payload, no link-mass randomisation (what a
robot's designer knows); ``config.model = "oracle"`` hands it the env's exact model, for study.
"""

from __future__ import annotations

import dataclasses
from collections import defaultdict
from dataclasses import dataclass
from typing import Any, Literal, Protocol, runtime_checkable

import gymnasium as gym
import mujoco
import numpy as np
from numpy.typing import NDArray

from wip_gym.robot_model import RobotModel
from wip_gym.scene import build_model

ModelChoice = Literal["nominal", "oracle"]


@runtime_checkable
class Policy(Protocol):
    """What the benchmark CLI and the video helper call."""

    def reset(self, observation: dict[str, NDArray[np.float64]], info: dict[str, Any]) -> None: ...

    def __call__(self, observation: dict[str, NDArray[np.float64]]) -> NDArray[np.float64]: ...

    @property
    def diagnostics(self) -> dict[str, NDArray[np.float64]]: ...


@dataclass(frozen=True)
class TaskInfo:
    """What a controller may know about the task, read from the env at ``for_env``.

    Attributes:
        goal: goal ``(X, Y)`` of the axle midpoint in world (planar: ``(x, 0)``).
        cup_friction: tray-cup friction coefficient, None without a cup.
        control_dt: the env's step (s).
        torque_low, torque_high: the action bounds (the actuators' torque limits).
        model_choice: ``nominal`` or ``oracle`` (recorded in the scenario).
    """

    goal: NDArray[np.float64]
    cup_friction: float | None
    control_dt: float
    torque_low: NDArray[np.float64]
    torque_high: NDArray[np.float64]
    model_choice: ModelChoice


def controller_model(env: gym.Env, choice: ModelChoice) -> mujoco.MjModel:
    """The MuJoCo model a controller plans with: ``nominal`` (robot + tray, no cup, no payload,
    no randomisation, the env's wheel torque limit) or ``oracle`` (the env's own model).

    A free tray (``tray_attachment="free"``) is welded at its nominal place in the nominal model
    (level on the hand at the reset pose, as in a welded-tray env): the designer knows the
    tray's mass, not its contact with the hand."""
    base = env.unwrapped
    if choice == "oracle":
        return base.model
    if choice != "nominal":
        raise ValueError(f"model must be 'nominal' or 'oracle', got {choice!r}")
    options = dataclasses.replace(
        base.scene_options, cup=False, payload_mass=0.0, tray_attachment="welded"
    )
    return build_model(options)


def task_info(env: gym.Env, choice: ModelChoice) -> TaskInfo:
    base = env.unwrapped
    return TaskInfo(
        goal=np.asarray(base.goal, dtype=float),
        cup_friction=base.cup_friction,
        control_dt=float(base.dt),
        torque_low=np.asarray(env.action_space.low, dtype=float),
        torque_high=np.asarray(env.action_space.high, dtype=float),
        model_choice=choice,
    )


def make_robot(env: gym.Env, choice: ModelChoice) -> RobotModel:
    """A ``RobotModel`` on the controller's own model and data."""
    return RobotModel(controller_model(env, choice))


class DiagnosticsRecorder:
    """Per-step signals, appended as floats or arrays, returned as stacked arrays.

    ``record`` keeps Python numbers as they are and copies arrays (a float64 array per number
    cost a microsecond each, a dozen per step); ``as_arrays`` converts to float64 once."""

    def __init__(self) -> None:
        self._signals: dict[str, list[Any]] = defaultdict(list)

    def clear(self) -> None:
        self._signals.clear()

    def record(self, **signals: Any) -> None:
        signals_ = self._signals
        for name, value in signals.items():
            signals_[name].append(value.copy() if isinstance(value, np.ndarray | list) else value)

    def as_arrays(self) -> dict[str, NDArray[np.float64]]:
        return {name: np.array(values, dtype=float) for name, values in self._signals.items()}
