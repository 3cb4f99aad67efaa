"""The disturbance-rejecting task wrapper on a plant whose model is wrong."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest

from controllers.low_level.disturbance_tasks import DisturbanceRejectingTask, ObserverSettings

DT = 1e-3


@dataclass
class Plant:
    """A 1-D hand: ``xdd = r xdd_cmd + d`` (the inverse dynamics' inertia off by ``1/r``, an
    unmodelled force ``d``), in the two attributes a task reads from a ``RobotModel``."""

    inertia_ratio: float
    disturbance: float
    x: float = 0.1
    nu: np.ndarray = field(default_factory=lambda: np.zeros(1))
    cache: dict = field(default_factory=dict)

    def step(self, command: float) -> None:
        self.nu[0] += DT * (self.inertia_ratio * command + self.disturbance)
        self.x += DT * self.nu[0]
        self.cache = {}  # what RobotModel.update does


@dataclass
class HoldTask:
    """Hold ``x`` at zero with the authors' orientation gains (Kp 150, Kv 50)."""

    kp: float = 150.0
    kv: float = 50.0
    name: str = "hold"

    def jacobian(self, robot: Plant) -> np.ndarray:
        return np.ones((1, 1))

    def error(self, robot: Plant) -> np.ndarray:
        return np.array([robot.x])

    def reference_acceleration(self, robot: Plant) -> np.ndarray:
        return np.array([-self.kp * robot.x - self.kv * robot.nu[0]])

    def weights(self) -> np.ndarray:
        return np.ones(1)


def settle(task, plant: Plant, seconds: float = 3.0) -> Plant:
    for _ in range(int(seconds / DT)):
        plant.step(float(task.reference_acceleration(plant)[0]))
    return plant


def test_the_estimate_restores_the_pd_despite_a_wrong_model() -> None:
    # a third of the inertia and a constant pull: the PD alone settles at d / (r Kp)
    plain = settle(HoldTask(), Plant(inertia_ratio=0.3, disturbance=-5.0))
    assert plain.x == pytest.approx(-5.0 / (0.3 * 150.0), rel=1e-3)
    task = DisturbanceRejectingTask(HoldTask(), ObserverSettings(DT, 50.0, 100.0))
    observed = settle(task, Plant(inertia_ratio=0.3, disturbance=-5.0))
    assert abs(observed.x) < 1e-4
    # the estimate is what the wrong model hides: r cmd + d = 0 at rest, cmd = -estimate
    assert task.estimate[0] == pytest.approx(-5.0 / 0.3, rel=1e-3)


def test_the_clamp_bounds_the_estimate() -> None:
    task = DisturbanceRejectingTask(HoldTask(), ObserverSettings(DT, 50.0, 2.0))
    plant = settle(task, Plant(inertia_ratio=0.3, disturbance=-5.0))
    assert task.estimate[0] == pytest.approx(-2.0)
    # the clamp leaves part of the disturbance to the PD: d + r * bound over r Kp
    assert plant.x == pytest.approx((-5.0 + 0.3 * 2.0) / (0.3 * 150.0), rel=1e-3)


def test_one_update_per_state_and_restart() -> None:
    task = DisturbanceRejectingTask(HoldTask(), ObserverSettings(DT, 50.0, 100.0))
    plant = Plant(inertia_ratio=0.3, disturbance=-5.0)
    first = task.reference_acceleration(plant)
    plant.step(float(first[0]))
    second = task.reference_acceleration(plant)
    estimate = task.estimate.copy()
    np.testing.assert_array_equal(task.reference_acceleration(plant), second)
    np.testing.assert_array_equal(task.estimate, estimate)
    assert estimate[0] != 0.0
    task.restart()
    plant.cache = {}
    task.reference_acceleration(plant)  # no previous step: the estimate is kept as it is
    np.testing.assert_array_equal(task.estimate, estimate)


def test_settings_are_checked() -> None:
    with pytest.raises(ValueError):
        ObserverSettings(DT, 0.0, 1.0)
