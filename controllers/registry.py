"""The controllers by name: the one place a controller is registered.

    from controllers.registry import controller_names, default_config, make_policy, register

    controller_names()                      # ['decoupled', 'decoupled-lqr', ...]
    config = default_config("unified", preset="paper")   # the frozen config dataclass
    policy = make_policy("unified", env, config)          # Controller.for_env(env, config)

A name maps to a controller class (a :class:`controllers.policy.PolicyBase` subclass, or any
class with ``for_env(env, config)`` returning a :class:`controllers.policy.Policy`), its config
dataclass and the config fields the name fixes (``unified-waiter`` is the hierarchical
controller with ``tray_mode="specific_force"``). Adding a controller is one call::

    register("my-controller", MyController, MyConfig, some_field=1.0)

A ``register`` call serves the process that makes it. Three ways reach every process a
command runs (``wip-bench`` itself, compare's ``--jobs`` workers, the sweep's Ray workers),
without editing this package (docs/extending.md §2):

* **an installed plug-in**: a distribution that declares an entry point in the group
  :data:`ENTRY_POINT_GROUP` (``wip_gym.controllers``). Its value names a module, whose import
  calls ``register`` (``my_controllers = "my_package.controllers"``), or a callable taking no
  argument that calls it (``my_controllers = "my_package.controllers:register_all"``); the
  entry point's name is only a label. Every process loads the group once, on its first
  question to the registry (:func:`load_plugins`); an entry point that fails to load raises
  :class:`PluginError` naming it.
* **``--import MODULE``** (repeatable) on ``wip-bench compare``, ``sweep`` and ``profile``: the
  command imports the module (:func:`import_modules`) before it reads its arguments' names, and
  hands the list to its workers, which import it before they make a policy. The module must be
  importable there (installed, or on ``PYTHONPATH``).
* an entry in ``_REGISTRY`` below, as the shipped controllers are (class and config as
  ``"module:Name"`` paths, imported on first use).

Order: the shipped names, then the plug-ins', then ``register`` calls (``--import`` modules
included); a name registered again is replaced. Classes are imported on first use, so importing
this module does not start JAX.
"""

from __future__ import annotations

import dataclasses
import importlib
import types
from collections.abc import Iterable
from dataclasses import dataclass
from importlib import metadata
from typing import Any

import gymnasium as gym

from controllers.policy import ModelChoice, Policy

PRESETS = ("paper",)
#: the entry-point group of controller plug-ins (module docstring)
ENTRY_POINT_GROUP = "wip_gym.controllers"


class PluginError(RuntimeError):
    """A plug-in's entry point that could not be loaded (its cause chained)."""


@dataclass(frozen=True)
class Registration:
    """A registered controller: its class and config class (each a class or a
    ``"module:Name"`` path, imported on first use) and the config fields its name fixes."""

    controller: Any
    config: Any
    fields: dict[str, Any]

    def controller_class(self) -> Any:
        return _load(self.controller)

    def config_class(self) -> Any:
        return _load(self.config)


def _load(target: Any) -> Any:
    if not isinstance(target, str):
        return target
    module, _, attribute = target.partition(":")
    return getattr(importlib.import_module(module), attribute)


_REGISTRY: dict[str, Registration] = {
    "decoupled": Registration(
        "controllers.baselines.decoupled:DecoupledController",
        "controllers.baselines.decoupled:DecoupledConfig",
        {},
    ),
    "decoupled-lqr": Registration(
        "controllers.baselines.decoupled:DecoupledLQRController",
        "controllers.baselines.decoupled:DecoupledLQRConfig",
        {},
    ),
    "decoupled-mpc": Registration(
        "controllers.baselines.decoupled_mpc:DecoupledMPCController",
        "controllers.baselines.decoupled_mpc:DecoupledMPCConfig",
        {},
    ),
    "unified": Registration(
        "controllers.hierarchical:HierarchicalController",
        "controllers.hierarchical:HierarchicalConfig",
        {"tray_mode": "level"},
    ),
    "unified-waiter": Registration(
        "controllers.hierarchical:HierarchicalController",
        "controllers.hierarchical:HierarchicalConfig",
        {"tray_mode": "specific_force"},
    ),
    "unified-upright": Registration(
        "controllers.upright:UprightController", "controllers.upright:UprightConfig", {}
    ),
}


# the plug-ins' state in this process: None (not loaded), "loading", "loaded"
_plugins: str | None = None


def load_plugins() -> list[str]:
    """Load every entry point of :data:`ENTRY_POINT_GROUP` (once per process; later calls do
    nothing) and return their ``name = value`` lines. The registry's questions call it, so a
    program need not; ``PluginError`` naming the entry point if one fails."""
    global _plugins
    if _plugins is not None:
        return []
    _plugins = "loading"  # a plug-in's own register calls must not load the group again
    loaded = []
    try:
        for entry in metadata.entry_points(group=ENTRY_POINT_GROUP):
            label = f"{entry.name} = {entry.value}"
            distribution = getattr(entry.dist, "name", None) or "an unknown distribution"
            try:
                target = entry.load()
                if not isinstance(target, types.ModuleType):
                    if not callable(target):
                        raise TypeError(f"{entry.value} is neither a module nor a callable")
                    target()
            except Exception as error:
                raise PluginError(
                    f"the {ENTRY_POINT_GROUP} entry point '{label}' of {distribution} failed: "
                    f"{type(error).__name__}: {error}"
                ) from error
            loaded.append(label)
    finally:
        _plugins = "loaded"
    return loaded


def import_modules(modules: Iterable[str]) -> None:
    """Import each module (``--import MODULE``), whose import registers its controllers.
    ``ValueError`` for a module that does not exist; an error inside the module propagates."""
    load_plugins()  # the plug-ins first, so that a module's register call wins
    for name in modules:
        if not isinstance(name, str) or not name:
            raise ValueError(f"--import takes a module name, got {name!r}")
        try:
            importlib.import_module(name)
        except ModuleNotFoundError as error:
            if error.name is None or not (name == error.name or name.startswith(error.name + ".")):
                raise  # a module the imported one needs: its own error
            raise ValueError(
                f"--import {name}: no module named {error.name!r} (install it, or put its "
                "directory on PYTHONPATH)"
            ) from None


def controller_names() -> list[str]:
    """Every registered name, in registration order (the plug-ins loaded first)."""
    load_plugins()
    return list(_REGISTRY)


def register(name: str, controller_cls: Any, config_cls: Any, **fields: Any) -> None:
    """Register ``controller_cls`` (with ``for_env(env, config)``) under ``name``, configured
    by ``config_cls`` (a frozen dataclass with a ``model`` field) with ``fields`` applied.
    Either class may be given as a ``"module:Name"`` path, imported on first use. A name
    already registered is replaced. ``ValueError`` for an empty name or a field the config
    class does not have (checked when the config class is a class)."""
    load_plugins()  # the plug-ins first: a later register call replaces theirs
    if not isinstance(name, str) or not name:
        raise ValueError(f"a controller name must be a non-empty string, got {name!r}")
    if not isinstance(config_cls, str):
        if not (isinstance(config_cls, type) and dataclasses.is_dataclass(config_cls)):
            raise ValueError(f"config_cls must be a dataclass class, got {config_cls!r}")
        known = {f.name for f in dataclasses.fields(config_cls)}
        unknown = sorted(set(fields) - known)
        if unknown:
            raise ValueError(
                f"{config_cls.__name__} has no fields {unknown}; valid: {sorted(known)}"
            )
    _REGISTRY[name] = Registration(controller_cls, config_cls, dict(fields))


def registration(name: str) -> Registration:
    """The registration of ``name``; ``ValueError`` naming the valid names."""
    load_plugins()
    if name not in _REGISTRY:
        raise ValueError(f"unknown controller {name!r}; valid: {controller_names()}")
    return _REGISTRY[name]


def default_config(name: str, preset: str | None = None) -> Any:
    """The config of ``name`` (its frozen dataclass) with the name's fields applied:
    ``preset=None`` the defaults, ``"paper"`` the class's ``paper()`` constructor (the authors'
    configuration). ``ValueError`` for an unknown name or preset, naming the valid ones."""
    entry = registration(name)
    config_cls = entry.config_class()
    if preset is None:
        return config_cls(**entry.fields)
    if preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r}; valid: {list(PRESETS)} or None")
    constructor = getattr(config_cls, preset, None)
    if constructor is None:
        raise ValueError(f"controller {name!r} ({config_cls.__name__}) has no preset {preset!r}")
    return dataclasses.replace(constructor(), **entry.fields)


def make_policy(
    name: str, env: gym.Env, config: Any = None, model: ModelChoice = "nominal"
) -> Policy:
    """``Controller.for_env(env, config)`` for the registered ``name``. Without ``config``:
    ``default_config(name)`` with ``model`` applied; with one, it is used as given (its own
    ``model``) and must be an instance of the name's config class."""
    entry = registration(name)
    config_cls = entry.config_class()
    if config is None:
        config = dataclasses.replace(default_config(name), model=model)
    elif not isinstance(config, config_cls):
        raise ValueError(
            f"controller {name!r} needs a {config_cls.__name__}, got {type(config).__name__}"
        )
    return entry.controller_class().for_env(env, config)
