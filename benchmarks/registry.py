"""Controllers by benchmark name. New controllers register here; the CLI needs no edit."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

import gymnasium as gym

# name -> (class import path, config import path, extra config fields)
_REGISTRY: dict[str, tuple[str, str, dict[str, Any]]] = {
    "decoupled": (
        "controllers.decoupled:DecoupledController",
        "controllers.decoupled:DecoupledConfig",
        {},
    ),
    "decoupled-mpc": (
        "controllers.decoupled_mpc:DecoupledMPCController",
        "controllers.decoupled_mpc:DecoupledMPCConfig",
        {},
    ),
    "unified": (
        "controllers.hierarchical:HierarchicalController",
        "controllers.hierarchical:HierarchicalConfig",
        {"tray_mode": "level"},
    ),
    "unified-waiter": (
        "controllers.hierarchical:HierarchicalController",
        "controllers.hierarchical:HierarchicalConfig",
        {"tray_mode": "specific_force"},
    ),
}


def controller_names() -> list[str]:
    return list(_REGISTRY)


def register(name: str, controller: str, config: str, **fields: Any) -> None:
    """Register a controller class (``module:Class``) with its config class and fields."""
    _REGISTRY[name] = (controller, config, fields)


def _load(path: str) -> Any:
    module, _, attribute = path.partition(":")
    return getattr(importlib.import_module(module), attribute)


def make_policy(name: str, env: gym.Env, model: str = "nominal") -> Callable[..., Any]:
    """``Controller.for_env(env, Config(model=model, **fields))`` for a registered name."""
    if name not in _REGISTRY:
        raise ValueError(f"unknown controller {name!r}; valid: {controller_names()}")
    controller, config, fields = _REGISTRY[name]
    return _load(controller).for_env(env, _load(config)(model=model, **fields))
