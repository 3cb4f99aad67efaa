"""``Jdot nu`` of tasks by a central finite difference: the controller's former fallback for a
task without an exact ``jdot_nu`` (``controllers.low_level.motion_probe``), kept here as the tests'
independent reference for the exact one."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]


def central_difference_jdot_nu(robot: RobotModel, tasks: Sequence[Any], eps: float = 1e-6) -> Array:
    """d/dt of the stacked ``J(q) nu`` at fixed ``nu``: the difference of ``J nu`` between the
    states ``(q +- eps nu, nu)`` on the floor (kinematics of a second model), over ``2 eps``."""
    probe = RobotModel(robot.model)
    q, nu = robot.q.copy(), robot.nu.copy()
    xy = robot.axle_position[:2]
    sides = []
    for sign in (1.0, -1.0):
        qpos, qvel = robot.full_state(q + sign * eps * nu, nu, xy)
        probe.update(qpos, qvel, dynamics=False)
        sides.append(np.concatenate([task.jacobian(probe) @ nu for task in tasks]))
    return (sides[0] - sides[1]) / (2 * eps)
