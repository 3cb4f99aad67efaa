"""Controllers of wip-gym as policies: ``Controller.for_env(env)``, ``reset``, ``__call__``.

    from controllers import HierarchicalController, make_policy

The names below are imported on first use (PEP 562), so ``import controllers`` alone does not
import JAX. It puts XLA's loop option in ``XLA_FLAGS`` if JAX has not started (the one setting
that cannot be scoped); the solvers scope float64 themselves, so a program needs no call
(``controllers.optimizer.jax_setup``, docs/DESIGN.md §4).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from controllers.optimizer import jax_setup as _jax_setup

_jax_setup.add_loop_flag()  # before JAX's backend starts, or the first solver warns once

if TYPE_CHECKING:
    from controllers.baselines.decoupled import (
        DecoupledConfig,
        DecoupledController,
        DecoupledLQRConfig,
        DecoupledLQRController,
    )
    from controllers.baselines.decoupled_mpc import DecoupledMPCConfig, DecoupledMPCController
    from controllers.hierarchical import HierarchicalConfig, HierarchicalController
    from controllers.high_level.planning import PlanConfig
    from controllers.policy import Policy, PolicyBase, TaskInfo
    from controllers.registry import (
        controller_names,
        default_config,
        default_controller_names,
        make_policy,
        register,
    )

_EXPORTS = {
    "DecoupledConfig": "controllers.baselines.decoupled",
    "DecoupledController": "controllers.baselines.decoupled",
    "DecoupledLQRConfig": "controllers.baselines.decoupled",
    "DecoupledLQRController": "controllers.baselines.decoupled",
    "DecoupledMPCConfig": "controllers.baselines.decoupled_mpc",
    "DecoupledMPCController": "controllers.baselines.decoupled_mpc",
    "HierarchicalConfig": "controllers.hierarchical",
    "HierarchicalController": "controllers.hierarchical",
    "PlanConfig": "controllers.high_level.planning",
    "Policy": "controllers.policy",
    "PolicyBase": "controllers.policy",
    "TaskInfo": "controllers.policy",
    "controller_names": "controllers.registry",
    "default_controller_names": "controllers.registry",
    "default_config": "controllers.registry",
    "make_policy": "controllers.registry",
    "register": "controllers.registry",
}

__all__ = [
    "DecoupledConfig",
    "DecoupledController",
    "DecoupledLQRConfig",
    "DecoupledLQRController",
    "DecoupledMPCConfig",
    "DecoupledMPCController",
    "HierarchicalConfig",
    "HierarchicalController",
    "PlanConfig",
    "Policy",
    "PolicyBase",
    "TaskInfo",
    "controller_names",
    "default_controller_names",
    "default_config",
    "make_policy",
    "register",
]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'controllers' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])
