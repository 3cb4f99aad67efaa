"""A controller plug-in written to a directory, as ``pip install --target DIR`` would leave it:
the package ``wipgym_balance_plugin`` and its ``wipgym_balance_plugin-0.1.dist-info`` whose
``entry_points.txt`` declares ``balance = wipgym_balance_plugin:register_all`` in the group
``wip_gym.controllers``; beside it ``my_imported_controllers.py``, a module for ``--import``.
Put the directory on ``PYTHONPATH`` and every process finds both (docs/extending.md §2).

The plug-in registers ``balance`` (the balance-in-place example of docs/extending.md §2: no
offline plan, no JAX) and ``broken`` (its control step raises); the module registers
``balance-imported`` (``balance`` with ``kp = 500``).
"""

from __future__ import annotations

from pathlib import Path

# The plug-in package: a balance-in-place controller without an offline plan (the example of
# docs/extending.md §2) and one whose control step raises, registered by a callable.
PLUGIN = '''
from dataclasses import dataclass

from controllers.low_level.posture import PostureHold
from controllers.policy import ModelChoice, PolicyBase
from controllers.registry import register


@dataclass(frozen=True)
class BalanceConfig:
    """Balance in place.

    Attributes:
        model: ``nominal`` or ``oracle``.
        kp: wheel torque per rad of theta (N m).
        kd: wheel torque per rad/s of theta (N m s).
    """

    model: ModelChoice = "nominal"
    kp: float = 400.0
    kd: float = 80.0


class BalanceController(PolicyBase):
    config_class = BalanceConfig

    def __init__(self, robot, task, config):
        super().__init__(robot, task, config)
        self._posture = PostureHold()

    def reset(self, observation, info):
        self.robot.update(observation["qpos"], observation["qvel"])
        self.begin_episode()
        self._posture.reset(self.robot)

    def __call__(self, observation):
        robot = self.robot
        robot.update(observation["qpos"], observation["qvel"])
        wheel = self.config.kp * robot.theta + self.config.kd * robot.thetad
        self._step += 1
        return self.finish(self.assemble((wheel, wheel), self._posture.torques(robot)))


class BrokenController(BalanceController):
    def __call__(self, observation):
        raise RuntimeError("the plug-in's broken controller")


def register_all():
    register("balance", BalanceController, BalanceConfig)
    register("broken", BrokenController, BalanceConfig)
'''
# A module for --import: registers at import time, under another name.
IMPORTED = """
from controllers.registry import register
from wipgym_balance_plugin import BalanceConfig, BalanceController

register("balance-imported", BalanceController, BalanceConfig, kp=500.0)
"""


def write_plugin(site: Path) -> Path:
    """Write the plug-in and the module into ``site``; return it."""
    (site / "wipgym_balance_plugin").mkdir()
    (site / "wipgym_balance_plugin" / "__init__.py").write_text(PLUGIN)
    info = site / "wipgym_balance_plugin-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: wipgym-balance-plugin\nVersion: 0.1\n"
    )
    (info / "entry_points.txt").write_text(
        "[wip_gym.controllers]\nbalance = wipgym_balance_plugin:register_all\n"
    )
    (site / "my_imported_controllers.py").write_text(IMPORTED)
    return site
