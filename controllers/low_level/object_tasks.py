"""The carried object's rows as task and constraint objects of the task QP, compiled or readable.

``unified-upright`` (docs/upright.md §2 and §3) adds three kinds of rows to the unified
controller's QP, each written here as an object the task QP takes beside the others, so that the
one-call step (``controllers.low_level.compiled_step``) computes them with the rest:

* :class:`TangentialForceTask`: the tangential specific force at the object's place on the plate
  toward zero (``ObjectBalance.tangential``);
* :class:`AxleAccelerationTask`: the axle's acceleration ``xdd`` toward a target (the MPC's);
* :class:`ObjectBalanceConstraint`: the object's balance rows ``G nu_dot + b <= 0``
  (``ObjectBalance.rows``). As a constraint of the task QP its rows are hard: the unconstrained
  minimiser is taken only when it meets them. ``controllers.low_level.priority_qp`` takes them
  as the QP's last constraint rows and makes them soft (weighted) or a level (strict).

Their readable rows call :class:`controllers.low_level.object_balance.ObjectBalance`, the
reference; their compiled rows (``compiled_tasks.tangential_force_rows``,
``axle_acceleration_rows``, ``object_balance_rows``) are held to it by
``tests/test_object_tasks.py``. A row's constant part, gravity's share included, is its
``jdot_nu`` (what the QP subtracts: ``b = w (xdd* - jdot_nu - J e)``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from controllers.low_level import compiled_tasks as ct
from controllers.low_level.constraints import Constraint
from controllers.low_level.motion_probe import MotionProbe
from controllers.low_level.object_balance import ObjectBalance
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]


class TangentialForceTask:
    """``(f_x, f_y)``, the tangential specific force the tray's motion puts on the object at its
    place (tray frame, in g; ``ObjectBalance.tangential``), toward zero with ``weight``. Its rows
    are read at ``robot``'s state (the one the task QP is given)."""

    compiled_kind: ClassVar[int | None] = ct.TANGENTIAL_FORCE

    def __init__(
        self, balance: ObjectBalance, robot: RobotModel, weight: float, name: str = "tangential"
    ) -> None:
        if not (np.isfinite(weight) and weight >= 0):
            raise ValueError(f"weight must be finite and >= 0, got {weight!r}")
        self.balance, self.robot, self.weight, self.name = balance, robot, float(weight), name
        self.site = balance.site

    def jacobian(self, robot: RobotModel) -> Array:
        return self.balance.tangential(robot, None)[0]

    def reference_acceleration(self, robot: RobotModel) -> Array:
        return np.zeros(2)

    def weights(self) -> Array:
        return np.full(2, self.weight)

    def jdot_nu(self, probe: MotionProbe) -> Array:
        """The rows' constant part at the robot's state: the force at ``nu_dot = 0``."""
        return self.balance.tangential(self.robot, probe)[1]

    def parameters(self) -> list[float]:
        """``(place x, place y, weight)``."""
        x, y = self.balance.carried.place
        return [float(x), float(y), self.weight]


@dataclass
class AxleAccelerationTask:
    """The axle's acceleration ``xdd`` (``nu_dot[0]``) toward ``target`` with ``weight``."""

    weight: float
    target: float = 0.0
    name: str = "axle_acceleration"

    compiled_kind: ClassVar[int | None] = ct.AXLE_ACCELERATION

    def jacobian(self, robot: RobotModel) -> Array:
        row = np.zeros((1, robot.layout.n_min))
        row[0, 0] = 1.0
        return row

    def reference_acceleration(self, robot: RobotModel) -> Array:
        return np.array([self.target], dtype=float)

    def weights(self) -> Array:
        return np.array([self.weight], dtype=float)

    def jdot_nu(self, probe: MotionProbe) -> Array:
        return np.zeros(1)  # J is constant

    def parameters(self) -> list[float]:
        """``(target, weight)``."""
        return [float(self.target), float(self.weight)]


@dataclass
class ObjectBalanceConstraint(Constraint):
    """The object's balance rows ``G nu_dot + b <= 0`` (``ObjectBalance.rows``: friction,
    contact, tipping) as a constraint of the task QP, read at ``robot``'s state."""

    balance: ObjectBalance
    robot: RobotModel
    name: str = "object_balance"
    _parameters: list[float] = field(init=False, repr=False)

    compiled_kind: ClassVar[int | None] = ct.OBJECT_BALANCE

    def __post_init__(self) -> None:
        carried = self.balance.carried
        # what the compiled rows read, fixed with the object (ObjectBalance's own arrays)
        self._parameters = [
            *map(float, carried.place),
            float(carried.com_height),
            *map(float, carried.inertia_per_mass),
            *self.balance.wrench_rows.ravel().tolist(),
            *self.balance.constants.tolist(),
        ]

    @property
    def site(self) -> int:
        return self.balance.site

    @property
    def rows_count(self) -> int:
        return self.balance.rows_count

    def jacobian(self, robot: RobotModel) -> Array:
        return self.balance.rows(robot, None)[0]

    def jdot_nu(self, probe: MotionProbe) -> Array:
        """``b``, the rows' constant part at the robot's state."""
        return self.balance.rows(self.robot, probe)[1]

    def bounds(self, robot: RobotModel) -> tuple[Array, Array]:
        count = self.rows_count
        return np.full(count, -np.inf), np.zeros(count)

    def parameters(self) -> list[float]:
        """``(place x, place y, height, inertia per mass (3), the wrench's row map (rows x 6,
        row-major), the rows' constants)``: the same list at every step."""
        return self._parameters
