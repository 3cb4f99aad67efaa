"""Controllers of wip-gym as policies: ``Controller.for_env(env)``, ``reset``, ``__call__``."""

from controllers.decoupled import DecoupledConfig, DecoupledController
from controllers.policy import Policy, TaskInfo

__all__ = ["DecoupledConfig", "DecoupledController", "Policy", "TaskInfo"]
