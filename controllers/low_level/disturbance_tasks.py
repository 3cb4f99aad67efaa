"""Disturbance rejection for a low-level task: an estimate of its unmodelled acceleration.

The task QP computes torques by inverse dynamics of the *nominal* model (eq. ``iso3``), so an
unmodelled load at the hand (a payload, docs/DESIGN.md §7) shows up as a task-space acceleration the
QP did not ask for: the hand's inertia is larger than the model's, and gravity pulls on a
mass the model does not have. The PD law of the paper,

    xdd* = xdd_d - Kp (x - x_d) - Kv (xd - xd_d)

then holds the task with a stiffness divided by the inertia mismatch, and a destabilising
load (a mass above the wrist) can overcome it. Integral action on the position error alone
cannot restore the lost stiffness.

:class:`DisturbanceRejectingTask` wraps a task and subtracts an estimate ``d_hat`` of that
unmodelled acceleration from its reference, time-delay estimation in the task's space
(Youcef-Toumi and Ito, "A time delay controller for systems with unknown dynamics", ASME
J. Dyn. Sys. Meas. Control 112(1), 1990), low-pass filtered:

    d_meas(k) = (J nu)(k) - (J nu)(k-1)) / dt - xdd*(k-1)        measured minus commanded
    d_hat(k)  = d_hat(k-1) + alpha (d_meas(k) - d_hat(k-1)),      alpha = dt w / (1 + dt w)
    xdd*(k)   = PD(k) - clip(d_hat(k), -bound, bound)

The update is integral action on the acceleration residual with a clamp as anti-windup: a
constant disturbance is cancelled exactly (the PD then reaches zero error), and an inertia
mismatch ``M_true > M_nominal`` is made up for below the bandwidth ``w``. The residual also
holds what the QP could not give the task (its trade-off with the other tasks and the
torque limits): the estimate then raises the task's priority within the bound.

The wrapper composes with any task of ``controllers.low_level.tasks`` (``jacobian``, ``error``,
``weights``, ``reference_acceleration``, ``name``). The estimate is advanced once per robot
state (memoised in ``robot.cache``, which every ``RobotModel.update`` clears), so it is called
once per control step however often the QP asks. A compiled task stack that advanced it marks
the entry :data:`ADVANCED_IN_MEMORY` instead (the command is then the memory's last command row,
copied at its first read here).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from controllers.low_level.motion_probe import MotionProbe
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]


class _AdvancedInMemory:
    """The type of :data:`ADVANCED_IN_MEMORY`."""

    def __repr__(self) -> str:
        return "ADVANCED_IN_MEMORY"

    def __reduce__(self) -> str:
        return "ADVANCED_IN_MEMORY"  # the one marker: a copy or a pickle of a cache keeps it


#: a ``robot.cache`` entry of an observer advanced at this state by a compiled task stack
#: (``controllers.low_level.task_stack``): its command is row 2 of its ``memory``, which the
#: stack's compiled step wrote (one marker per observer instead of a copy of its rows)
ADVANCED_IN_MEMORY = _AdvancedInMemory()


class AccelerationTask(Protocol):
    """The interface of a task of ``controllers.low_level.tasks``."""

    name: str

    def jacobian(self, robot: RobotModel) -> Array: ...

    def error(self, robot: RobotModel) -> Array: ...

    def reference_acceleration(self, robot: RobotModel) -> Array: ...

    def weights(self) -> Array: ...

    def jdot_nu(self, probe: MotionProbe) -> Array: ...


@dataclass(frozen=True)
class ObserverSettings:
    """Settings of one task's disturbance estimate.

    Attributes:
        dt: time between two control steps (s): the estimate's finite difference.
        bandwidth: ``w`` (rad/s) of the first-order filter on the measured residual.
        bound: clamp on each component of ``d_hat`` (the task's acceleration units).
    """

    dt: float
    bandwidth: float
    bound: float

    def __post_init__(self) -> None:
        if not (self.dt > 0 and self.bandwidth > 0 and self.bound > 0):
            raise ValueError(f"dt, bandwidth and bound must be positive, got {self}")

    @property
    def alpha(self) -> float:
        """Gain of the discrete first-order filter (backward Euler)."""
        return self.dt * self.bandwidth / (1.0 + self.dt * self.bandwidth)


class DisturbanceRejectingTask:
    """A task whose reference acceleration is corrected by the estimate of its unmodelled
    acceleration (see the module docstring)."""

    def __init__(self, task: AccelerationTask, settings: ObserverSettings) -> None:
        self.task = task
        self.settings = settings
        self.name = task.name
        # the whole state in one array, shared with the compiled task stack
        # (controllers.low_level.compiled_tasks): rows estimate, last J nu, last command, and
        # [1 when a last step exists, 0, ...]
        self.memory = np.zeros((4, len(task.weights())))
        self.cache_key = ("disturbance_rejecting_task", id(self))
        self._alpha = settings.alpha
        self._bound = settings.bound
        # the wrapped task's own J nu when it has one (shared with its PD law), else J @ nu
        self._velocity = getattr(task, "velocity", None)

    @property
    def estimate(self) -> Array:
        """``d_hat``, the current estimate (a view on :attr:`memory`)."""
        return self.memory[0]

    def adopt_memory(self, buffer: Array) -> None:
        """Keep the state in ``buffer`` (same shape) from now on, its current values copied:
        the compiled task stack holds every observer's state in one array."""
        if buffer.shape != self.memory.shape:
            raise ValueError(f"memory of shape {self.memory.shape} expected, got {buffer.shape}")
        buffer[:] = self.memory
        self.memory = buffer

    def restart(self) -> None:
        """Forget the last step (after a reset, or a jump in the state); keep the estimate."""
        self.memory[3, 0] = 0.0

    def jacobian(self, robot: RobotModel) -> Array:
        return self.task.jacobian(robot)

    def error(self, robot: RobotModel) -> Array:
        return self.task.error(robot)

    def weights(self) -> Array:
        return self.task.weights()

    def jdot_nu(self, probe: MotionProbe) -> Array:
        """The wrapped task's exact ``Jdot nu`` (``controllers.low_level.motion_probe``)."""
        return self.task.jdot_nu(probe)

    def reference_acceleration(self, robot: RobotModel) -> Array:
        cached = robot.cache.get(self.cache_key)
        if cached is not None:
            if cached is ADVANCED_IN_MEMORY:  # a compiled stack advanced it at this state
                cached = robot.cache[self.cache_key] = self.memory[2].copy()
            return cached  # type: ignore[return-value]
        velocity = (
            self._velocity(robot)
            if self._velocity is not None
            else self.task.jacobian(robot) @ robot.nu
        ).tolist()
        memory = self.memory
        if memory[3, 0] != 0.0:
            # per component in Python floats (the same IEEE arithmetic as NumPy's, without a
            # NumPy call per operation on a 3-vector); the clamp is np.clip's
            previous_velocity, previous_command = memory[1].tolist(), memory[2].tolist()
            dt, alpha, bound = self.settings.dt, self._alpha, self._bound
            values = memory[0].tolist()
            for i, value in enumerate(values):
                measured = (velocity[i] - previous_velocity[i]) / dt - previous_command[i]
                value += alpha * (measured - value)
                values[i] = min(max(value, -bound), bound)
            memory[0] = values
        command = self.task.reference_acceleration(robot) - memory[0]
        memory[1] = velocity
        memory[2] = command
        memory[3, 0] = 1.0
        robot.cache[self.cache_key] = command
        return command
