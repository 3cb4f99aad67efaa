"""Linear constraints of the task QP beside its tasks: rows ``lower <= G nu_dot + Jdot nu <=
upper`` over the minimal accelerations.

A constraint is written as a task is (``controllers.low_level.tasks``), with bounds in place of
the PD law: ``jacobian(robot)`` (``G``, over ``nu``), ``jdot_nu(probe)`` (its drift at the
robot's state, exact, from ``controllers.low_level.motion_probe``) and ``bounds(robot)`` (the
lower and upper bound of each row). The task QP (``controllers.low_level.task_qp``) turns them
into rows over its variables with the isolated dynamics, ``nu_dot = E qdd + e``, after the
actuators' and the joint limits' (``controllers.low_level.kernel``), and its unconstrained
shortcut is taken only when the minimiser meets them too. A class with compiled rows
(``compiled_kind``, ``parameters()``: ``controllers.low_level.compiled_tasks``) runs on the
one-call step; any other on the readable path.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from controllers.low_level import compiled_tasks as ct
from controllers.low_level.motion_probe import MotionProbe
from controllers.low_level.tasks import floats
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]


class Constraint:
    """The base of the QP's constraints (module docstring): a subclass gives ``jacobian``,
    ``jdot_nu``, ``bounds`` and a ``name``; with compiled rows, ``compiled_kind`` and
    ``parameters()``."""

    compiled_kind: ClassVar[int | None] = None
    name: str

    def jacobian(self, robot: RobotModel) -> Array:
        """``G``, ``(m, n_min)``: the constrained rows over ``nu``."""
        raise NotImplementedError(f"{type(self).__name__} must give jacobian(robot)")

    def jdot_nu(self, probe: MotionProbe) -> Array:
        """``Jdot nu`` of the rows at the robot's state (``m``,)."""
        raise NotImplementedError(f"{type(self).__name__} must give jdot_nu(probe)")

    def bounds(self, robot: RobotModel) -> tuple[Array, Array]:
        """``(lower, upper)`` of ``G nu_dot + Jdot nu`` (``m``, each)."""
        raise NotImplementedError(f"{type(self).__name__} must give bounds(robot)")

    def parameters(self) -> list[float]:
        """The numbers this constraint's compiled rows read, in their order."""
        raise NotImplementedError(f"{type(self).__name__} has no compiled rows")


@dataclass
class AccelerationBound(Constraint):
    """Bounds on minimal accelerations: ``lower <= nu_dot[columns] <= upper`` (one bound per
    column, or one for all), e.g. a joint that must not accelerate faster than a gearbox
    allows."""

    columns: NDArray[np.intp]
    lower: Any
    upper: Any
    name: str = "acceleration_bound"

    compiled_kind: ClassVar[int | None] = ct.ACCELERATION_BOUND

    def jacobian(self, robot: RobotModel) -> Array:
        rows = np.zeros((len(self.columns), robot.layout.n_min))
        rows[np.arange(len(self.columns)), self.columns] = 1.0
        return rows

    def jdot_nu(self, probe: MotionProbe) -> Array:
        return np.zeros(len(self.columns))  # G is constant

    def bounds(self, robot: RobotModel) -> tuple[Array, Array]:
        count = len(self.columns)
        return (
            np.array(floats(self.lower, count, self, "lower bounds")),
            np.array(floats(self.upper, count, self, "upper bounds")),
        )

    def parameters(self) -> list[float]:
        """``(lower bounds, upper bounds)``, one of each per column."""
        count = len(self.columns)
        return [
            *floats(self.lower, count, self, "lower bounds"),
            *floats(self.upper, count, self, "upper bounds"),
        ]
