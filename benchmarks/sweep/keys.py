"""Which override keys a sweep may set, and which values they take.

The keys are those of ``wip-bench compare --set``: ``env.<argument>`` (an argument of the env's
constructor), ``plan.<field>`` (the offline plan every controller of an episode shares,
:class:`controllers.planning.PlanConfig`) and ``<controller>.<dotted path>`` (a field of that
controller's config dataclass). :func:`validate_key` and :func:`validate_value` are the only two
functions the spec parser asks; they read the env's signature and the config dataclasses, so a
new env argument or config field is a valid key without an edit here.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import math
from collections.abc import Sequence
from typing import Any

import gymnasium as gym

from benchmarks.scenario import resolve_env_id

# Constructor arguments that are not task parameters (the env's identity and its rendering).
_NOT_ENV_KEYS = frozenset({"self", "robot", "tray", "render_mode", "width", "height"})
# The plan's acceleration cap has two spellings besides a number (m/s^2): the cup-safe cap
# (``0.5 mu g`` from the scenario's cup friction) and no cap at all, so that cup friction and
# plan aggressiveness are independent axes.
A_MAX_SPELLINGS = {"cup_safe": None, "none": math.inf}


def _env_class(env_id: str) -> type:
    entry_point = gym.spec(env_id).entry_point
    if not isinstance(entry_point, str):
        return entry_point  # type: ignore[return-value]
    module, _, name = entry_point.partition(":")
    return getattr(importlib.import_module(module), name)


def env_arguments(env_id: str) -> dict[str, Any]:
    """The env's task arguments and their defaults, read from the constructors of its class and
    its bases (the task classes take ``**kwargs`` and pass them on)."""
    arguments: dict[str, Any] = {}
    for cls in reversed(_env_class(resolve_env_id(env_id)).__mro__):
        init = cls.__dict__.get("__init__")
        if init is None:
            continue
        for name, parameter in inspect.signature(init).parameters.items():
            if name in _NOT_ENV_KEYS or parameter.kind in (
                inspect.Parameter.VAR_KEYWORD,
                inspect.Parameter.VAR_POSITIONAL,
            ):
                continue
            arguments[name] = parameter.default
    return arguments


def _controller_config_class(controller: str) -> type:
    from benchmarks import registry

    if controller not in registry.controller_names():
        raise ValueError(f"unknown controller {controller!r}; valid: {registry.controller_names()}")
    _, config_path, _ = registry._REGISTRY[controller]
    return registry._load(config_path)


def _field_default(field: dataclasses.Field[Any]) -> Any:
    if field.default is not dataclasses.MISSING:
        return field.default
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    return None


def _resolve_path(config_class: type, path: str, key: str) -> Any:
    """The default at a dotted path through nested config dataclasses; ValueError naming the
    key and the valid fields at the first part that does not exist."""
    value: Any = config_class()
    for part in path.split("."):
        if not dataclasses.is_dataclass(value):
            raise ValueError(f"unknown key {key!r}: {part!r} is below a non-config field")
        names = [f.name for f in dataclasses.fields(value)]
        if part not in names:
            raise ValueError(f"unknown key {key!r}: no field {part!r}; valid: {names}")
        value = _field_default(next(f for f in dataclasses.fields(value) if f.name == part))
    return value


def key_default(key: str, env_id: str, controllers: Sequence[str]) -> Any:
    """The default value of a valid key (ValueError naming it if it is not valid)."""
    scope, dot, path = key.partition(".")
    if not dot or not path:
        raise ValueError(
            f"unknown key {key!r}: expected env.<argument>, plan.<field> or <controller>.<path>"
        )
    if scope == "env":
        arguments = env_arguments(env_id)
        if path not in arguments:
            raise ValueError(
                f"unknown key {key!r}: {env_id} has no argument {path!r}; "
                f"valid: {sorted(arguments)}"
            )
        return arguments[path]
    if scope == "plan":
        from controllers.planning import PlanConfig

        return _resolve_path(PlanConfig, path, key)
    if scope in controllers:
        return _resolve_path(_controller_config_class(scope), path, key)
    raise ValueError(
        f"unknown key {key!r}: {scope!r} is neither env, plan nor one of the sweep's "
        f"controllers {list(controllers)}"
    )


def validate_key(key: str, env_id: str, controllers: Sequence[str]) -> None:
    """ValueError naming ``key`` (and the valid choices) unless a sweep of ``controllers`` on
    ``env_id`` may set it."""
    key_default(key, env_id, controllers)


def _kind(value: Any) -> str:
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int | float):
        return "number"
    if isinstance(value, str):
        return "string"
    if isinstance(value, list | tuple):
        return "array"
    if isinstance(value, dict):
        return "table"
    return type(value).__name__


def check_json_value(key: str, value: Any) -> None:
    """Values are JSON (finite numbers, strings, booleans, arrays and tables of them)."""
    kind = _kind(value)
    if kind == "number" and not math.isfinite(value):
        raise ValueError(f"bad value for {key!r}: {value} is not finite")
    if kind == "array":
        for item in value:
            check_json_value(key, item)
    elif kind == "table":
        for item in value.values():
            check_json_value(key, item)
    elif kind not in ("bool", "number", "string"):
        raise ValueError(f"bad value for {key!r}: {value!r} ({kind}) is not a JSON value")


def validate_value(key: str, value: Any, env_id: str, controllers: Sequence[str]) -> None:
    """ValueError naming ``key`` unless ``value`` has the kind of the key's default (a number
    for a number, a string for a string, ...; anything for a default of None).
    ``plan.a_max`` also takes ``"cup_safe"`` and ``"none"`` (:data:`A_MAX_SPELLINGS`)."""
    check_json_value(key, value)
    default = key_default(key, env_id, controllers)
    if key == "plan.a_max":
        if isinstance(value, str) and value not in A_MAX_SPELLINGS:
            raise ValueError(
                f"bad value for {key!r}: {value!r}; a number (m/s^2) or one of "
                f"{sorted(A_MAX_SPELLINGS)}"
            )
        if _kind(value) == "number" and value <= 0:
            raise ValueError(f"bad value for {key!r}: {value} must be positive")
        if _kind(value) not in ("number", "string"):
            raise ValueError(f"bad value for {key!r}: {value!r} is not a number or a string")
        return
    if default is None or dataclasses.is_dataclass(default):
        if dataclasses.is_dataclass(default):
            raise ValueError(f"bad key {key!r}: it names a whole config; set one of its fields")
        return
    expected = _kind(default)
    if key.startswith("env.") and {expected, _kind(value)} == {"array", "number"}:
        return  # env.goal is X or [X, Y]: the env's constructor checks (spec.check_env_values)
    if _kind(value) != expected:
        raise ValueError(
            f"bad value for {key!r}: {value!r} is a {_kind(value)}, expected a {expected} "
            f"like its default {default!r}"
        )


# Presets the episode runner knows (benchmarks/sweep/_shim.py knows none yet).
PRESETS: tuple[str, ...] = ()


def validate_preset(preset: str | None, env_id: str) -> None:
    """ValueError naming ``preset`` unless the episode runner has it (None: no preset)."""
    if preset is not None and preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r} for {env_id}; valid: {list(PRESETS)}")
