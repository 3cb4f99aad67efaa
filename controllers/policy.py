"""The policy protocol every wip-gym controller follows (docs/DESIGN.md §7).

    policy = Controller.for_env(env, config=None)   # reads the task, builds the nominal model
    policy.reset(observation, info)                  # all slow work: linearisation, planning
    action = policy(observation)                     # one control step
    policy.diagnostics                               # dict of signals a person would plot
    policy.counters                                  # episode counts (clips, QP fallbacks, ...)

A policy reads only the observation. It keeps its own MuJoCo data (a ``RobotModel``), rebuilt
from ``qpos``/``qvel``, and never reads the env's simulator. ``for_env`` builds a **nominal**
mass model: the robot with its tray, no cup, no payload, no link-mass randomisation (what a
robot's designer knows); ``config.model = "oracle"`` hands it the env's exact model, for study.
"""

from __future__ import annotations

import dataclasses
from collections import defaultdict
from dataclasses import dataclass
from typing import Any, ClassVar, Literal, Protocol, Self, runtime_checkable

import gymnasium as gym
import mujoco
import numpy as np
from numba import njit
from numpy.typing import NDArray

from wip_gym.envs.base import wip_env
from wip_gym.robot_model import RobotModel
from wip_gym.scene import SceneOptions, build_spec

ModelChoice = Literal["nominal", "oracle"]


@runtime_checkable
class Policy(Protocol):
    """What the benchmark CLI, the rollout and the video helper call (the one protocol;
    :class:`PolicyBase` implements it)."""

    def reset(self, observation: dict[str, NDArray[np.float64]], info: dict[str, Any]) -> None: ...

    def __call__(self, observation: dict[str, NDArray[np.float64]]) -> NDArray[np.float64]: ...

    @property
    def diagnostics(self) -> dict[str, NDArray[np.float64]]: ...

    @property
    def counters(self) -> dict[str, float]: ...


class PolicyConfig(Protocol):
    """What ``PolicyBase.for_env`` reads of a policy's config: which model it plans with."""

    @property
    def model(self) -> ModelChoice: ...


@dataclass(frozen=True)
class TaskInfo:
    """What a controller may know about the task, read from the env at ``for_env``.

    Attributes:
        goal: goal ``(X, Y)`` of the axle midpoint in world (planar: ``(x, 0)``).
        cup_friction: tray-cup friction coefficient, None without a cup.
        control_dt: the env's step (s).
        torque_low, torque_high: the action bounds (the actuators' torque limits).
        model_choice: ``nominal`` or ``oracle`` (recorded in the scenario).
        free_tray: with a free tray, the scene options it was built from (the designer knows
            the tray, its supports and their friction, not how the contacts stand); None
            otherwise.
    """

    goal: NDArray[np.float64]
    cup_friction: float | None
    control_dt: float
    torque_low: NDArray[np.float64]
    torque_high: NDArray[np.float64]
    model_choice: ModelChoice
    free_tray: SceneOptions | None = None


def controller_model(env: gym.Env, choice: ModelChoice) -> mujoco.MjModel:
    """The MuJoCo model a controller plans with: ``nominal`` (robot + tray, no cup, no payload,
    no randomisation, the env's wheel torque limit) or ``oracle`` (the env's own model).

    A free tray (``tray_attachment="free"``) is welded in the nominal model where it rests on
    the hand (the env's ``tray_rest`` site: on Krang's finger plates 2.9 deg from level): the
    designer knows the tray's mass and where it sits, not its contact with the hand."""
    base = wip_env(env)
    if choice == "oracle":
        return base.model
    if choice != "nominal":
        raise ValueError(f"model must be 'nominal' or 'oracle', got {choice!r}")
    return nominal_spec(env).compile()


def nominal_spec(env: gym.Env) -> mujoco.MjSpec:
    """The ``MjSpec`` of :func:`controller_model`'s ``nominal`` model (a controller that adds
    to it compiles its own)."""
    base = wip_env(env)
    options = dataclasses.replace(
        base.scene_options, cup=False, payload_mass=0.0, tray_attachment="welded"
    )
    if base.scene_options.tray_attachment == "free":
        rest = base.model.site("tray_rest")
        options = dataclasses.replace(options, tray_weld=(*rest.pos.tolist(), *rest.quat.tolist()))
    return build_spec(options)


def task_info(env: gym.Env, choice: ModelChoice) -> TaskInfo:
    base = wip_env(env)
    return TaskInfo(
        goal=np.asarray(base.goal, dtype=np.float64),
        cup_friction=base.cup_friction,
        control_dt=float(base.dt),
        torque_low=np.asarray(base.action_space.low, dtype=np.float64),
        torque_high=np.asarray(base.action_space.high, dtype=np.float64),
        model_choice=choice,
        free_tray=base.scene_options if base.scene_options.tray_attachment == "free" else None,
    )


def make_robot(env: gym.Env, choice: ModelChoice) -> RobotModel:
    """A ``RobotModel`` on the controller's own model and data."""
    return RobotModel(controller_model(env, choice))


class DiagnosticsRecorder:
    """Per-step signals, appended as floats or arrays, returned as stacked arrays.

    ``record`` keeps Python numbers as they are and copies arrays (a float64 array per number
    cost a microsecond each, a dozen per step); ``record_row`` appends one step's values of a
    fixed tuple of names as one tuple (no keywords, no per-value checks: the caller passes
    arrays it will not change); ``as_arrays`` converts to float64 once."""

    def __init__(self) -> None:
        self._signals: dict[str, list[Any]] = defaultdict(list)
        self._rows: dict[tuple[str, ...], list[tuple[Any, ...]]] = {}

    def clear(self) -> None:
        self._signals.clear()
        self._rows.clear()

    def record(self, **signals: Any) -> None:
        signals_ = self._signals
        for name, value in signals.items():
            signals_[name].append(value.copy() if isinstance(value, np.ndarray | list) else value)

    def record_row(self, names: tuple[str, ...], values: tuple[Any, ...]) -> None:
        """Append ``values`` (one per name of ``names``, the same tuple of names every step)
        as they are: arrays among them must not change afterwards (pass copies)."""
        if len(values) != len(names):
            raise ValueError(f"{len(names)} names, {len(values)} values")
        rows = self._rows.get(names)
        if rows is None:
            rows = self._rows[names] = []
        rows.append(values)

    def as_arrays(self) -> dict[str, NDArray[np.float64]]:
        arrays = {name: np.array(values, dtype=float) for name, values in self._signals.items()}
        for names, rows in self._rows.items():
            for i, name in enumerate(names):
                arrays[name] = np.array([row[i] for row in rows], dtype=float)
        return arrays


@njit(cache=True)
def _clip_and_measure(
    action: NDArray[np.float64],
    low: NDArray[np.float64],
    high: NDArray[np.float64],
    tolerance: NDArray[np.float64],
    clipped: NDArray[np.float64],
) -> tuple[bool, float, bool]:
    """``clipped`` = ``action`` inside ``[low, high]`` (``clipped`` may be ``action``: each
    entry is read before it is written); returns (every entry finite, the largest excess over
    a bound (0 inside), any clipped entry within ``tolerance`` of a bound). One compiled call
    for what were eight NumPy calls per step."""
    finite, excess, at_limit = True, 0.0, False
    for i in range(len(action)):
        value = action[i]
        if not np.isfinite(value):
            finite = False
        excess = max(excess, value - high[i], low[i] - value)
        value = min(max(value, low[i]), high[i])
        clipped[i] = value
        if value >= high[i] - tolerance[i] or value <= low[i] + tolerance[i]:
            at_limit = True
    return finite, excess, at_limit


class ClipCounter:
    """The final clip of a policy's action to the action bounds, counted, never silent.

    ``clip(action)`` returns the action inside ``[low, high]`` and counts the steps whose action
    had to be clipped (``clipped_steps``), the largest amount by which a torque exceeded its
    bound (``max_clip_excess``, N m) and the steps with any applied torque at its bound
    (``actuator_limit_steps``: clipped, or placed there by the controller, e.g. by an active QP
    torque constraint; within ``1e-6`` of the bound's size)."""

    def __init__(self, low: NDArray[np.float64], high: NDArray[np.float64]) -> None:
        # the arrays given, not copies: a change of their values in place (a controller's
        # torque limits narrowed) reaches the clip, as it always did
        low, high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
        if low.ndim != 1 or low.shape != high.shape:
            raise ValueError(
                f"action bounds must be two 1-D arrays of one length, got shapes {low.shape} "
                f"and {high.shape}"
            )
        if np.any(low > high):
            raise ValueError(f"action bounds must be ordered (low <= high), got {low}, {high}")
        # not assignable: the compiled clip reads them and the tolerance made from them with
        # the shape checked here (a shorter high let a torque through unclipped)
        self._low, self._high = low, high
        self._at_limit_tolerance = 1e-6 * np.maximum(1.0, np.maximum(-low, high))
        self.reset()

    @property
    def low(self) -> NDArray[np.float64]:
        """The lower bounds (not assignable: a counter with other bounds is a new one)."""
        return self._low

    @property
    def high(self) -> NDArray[np.float64]:
        """The upper bounds (not assignable)."""
        return self._high

    def reset(self) -> None:
        self.clipped_steps = 0
        self.max_clip_excess = 0.0
        self.actuator_limit_steps = 0
        self.last_excess = 0.0

    def clip(self, action: NDArray[np.float64]) -> NDArray[np.float64]:
        # a copy, clipped in place and returned: the compiled check sees one array type (a
        # read-only or strided action, a JAX array's view, would compile it again), and the
        # caller's array is left as it was
        given = action
        clipped = np.array(action, dtype=np.float64)
        if clipped.shape != self._low.shape:
            raise ValueError(f"action must have shape {self._low.shape}, got {clipped.shape}")
        finite, excess, at_limit = _clip_and_measure(
            clipped, self._low, self._high, self._at_limit_tolerance, clipped
        )
        if not finite:
            raise ValueError(f"the controller produced a non-finite action: {given}")
        self.last_excess = excess
        if excess > 0.0:
            self.clipped_steps += 1
            self.max_clip_excess = max(self.max_clip_excess, excess)
        if at_limit:
            self.actuator_limit_steps += 1
        return clipped

    @property
    def counters(self) -> dict[str, float]:
        return {
            "clipped_steps": float(self.clipped_steps),
            "max_clip_excess": float(self.max_clip_excess),
            "actuator_limit_steps": float(self.actuator_limit_steps),
        }


class PolicyBase:
    """What every wip-gym policy shares: ``for_env``, ``name``, ``diagnostics``, ``counters``,
    the wheel-torque assembly and the final, counted clip to the action bounds.

    A subclass sets ``config_class`` (a frozen dataclass with a ``model`` field) and
    ``registry_name``, calls :meth:`begin_episode` in its ``reset``, builds its action with
    :meth:`assemble` (or its own map) and returns :meth:`finish` of it from ``__call__``; it
    adds its own counters by overriding :meth:`controller_counters`."""

    config_class: ClassVar[type[PolicyConfig]]
    registry_name: ClassVar[str] = "policy"

    def __init__(self, robot: RobotModel, task: TaskInfo, config: Any) -> None:
        self.robot = robot
        self.task = task
        self.config = config
        self._recorder = DiagnosticsRecorder()
        self._clip = ClipCounter(task.torque_low, task.torque_high)
        self._step = 0

    @classmethod
    def for_env(cls, env: gym.Env, config: Any = None) -> Self:
        """The policy for ``env`` (reads the task, builds the nominal or oracle model)."""
        config = cls.config_class() if config is None else config
        if not isinstance(config, cls.config_class):
            raise ValueError(
                f"{cls.__name__} needs a {cls.config_class.__name__}, got {type(config).__name__}"
            )
        return cls(make_robot(env, config.model), task_info(env, config.model), config)

    @property
    def name(self) -> str:
        return self.registry_name

    def begin_episode(self) -> None:
        """Clear the diagnostics, the counters and the step count (call from ``reset``)."""
        self._recorder.clear()
        self._clip.reset()
        self._step = 0

    def assemble(
        self, wheels: tuple[float, float], joints: NDArray[np.float64] | None = None
    ) -> NDArray[np.float64]:
        """The action vector from the wheel torques ``(tau_L, tau_R)`` (N m, each wheel's own
        actuator torque) and the body joints' torques (``layout.joint_actuators`` order)."""
        lay = self.robot.layout
        action = np.zeros(self.robot.model.nu)
        wl, wr = lay.wheel_actuators
        action[wl], action[wr] = wheels
        if joints is not None:
            action[list(lay.joint_actuators)] = joints
        return action

    def finish(self, action: NDArray[np.float64]) -> NDArray[np.float64]:
        """``action`` clipped to the action bounds, the clip counted (:class:`ClipCounter`)."""
        return self._clip.clip(action)

    def controller_counters(self) -> dict[str, float]:
        """The subclass's own counters (QP fallbacks, MPC rejections, ...)."""
        return {}

    @property
    def counters(self) -> dict[str, float]:
        """Episode counts for the harness, reset at ``reset``: ``clipped_steps``,
        ``max_clip_excess`` (N m), ``actuator_limit_steps``, and the controller's own
        (``qp_fallbacks``, ``qp_failures``, ``mpc_rejections``, ``plan_violations``,
        ``plan_converged``, ``max_joint_deviation_rad`` where they apply)."""
        return {**self._clip.counters, **self.controller_counters()}

    @property
    def diagnostics(self) -> dict[str, NDArray[np.float64]]:
        """Per-step signals (see the subclass)."""
        return self._recorder.as_arrays()


def plan_counters(plan: Any) -> dict[str, float]:
    """``plan_violations`` (count) and ``plan_converged`` (1.0/0.0) of a ``Plan``."""
    return {
        "plan_violations": float(len(plan.violations)),
        "plan_converged": 1.0 if plan.converged else 0.0,
    }
