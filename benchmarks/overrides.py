"""``--set KEY=VALUE``: one grammar for every setting of a benchmark run, type-checked before
anything runs.

Keys (``wip-bench compare --list-keys`` prints them with their types, defaults and one line
each from where the setting is documented, :mod:`benchmarks.key_docs`):

* ``env.<argument>``: any argument of the env's constructor (``WIPEnv.__init__`` and the task
  class's own), e.g. ``env.cup_friction=0.2``, ``env.goal=[2, 1]``. The task's fixed ones
  (``robot``, ``tray``) and the rendering ones (``render_mode``, ``width``, ``height``) are not
  keys.
* ``plan.<field>[.<field>...]``: a field of the offline plan's ``PlanConfig``, applied to every
  ``PlanConfig`` inside every controller of the run (found by walking the config dataclasses),
  so that every controller shares the same plan, e.g. ``plan.a_max=2.5``. A controller of the
  run without an offline plan is left as it is (``RunSpec.not_applied`` names it; compare and
  the sweep say so); a run in which no controller has a plan refuses the key.
* ``<controller>.<field>[.<field>...]``: one controller's config, by its dotted path through
  the nested config dataclasses, e.g. ``unified.ee_position_weight=5``,
  ``unified.high_level.mpc.horizon_s=0.5``.

Values parse as JSON (``1``, ``2.5``, ``true``, ``null``, ``[2, 1]``, ``"text"``); text that is
not JSON is a string (``plan.a_max=none`` is ``"none"``). A value is checked against the
field's annotated type (an ``int`` is accepted for a ``float``, a list for a tuple) or, for an
env argument without an annotation, against the type of its default. An unknown key or a
wrong type raises ``OverrideError`` (a ``ValueError``, so the CLI exits with status 2) naming
the key.

Precedence (``resolve_run``): defaults, then the preset, then the named flags (``--goal``,
``--cup-friction``, ``--payload``, ``--model``, ...), then ``--set`` in the order given.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import json
import math
import types
import typing
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

import gymnasium as gym

from benchmarks import presets
from benchmarks.key_docs import config_field_doc, env_argument_docs
from controllers import registry
from wip_gym.envs.base import wip_env

FIXED_ENV_ARGUMENTS = ("robot", "tray")  # set by the task class
RENDER_ENV_ARGUMENTS = ("render_mode", "width", "height")  # how to draw, not what happens
_MISSING = object()


class OverrideError(ValueError):
    """A ``--set`` key that does not exist or a value of the wrong type."""


@dataclass(frozen=True)
class Setting:
    """One valid key: its annotated type, its default and one line saying what it means."""

    key: str
    type: Any
    default: Any
    description: str = ""


# ---------------------------------------------------------------------------- values and types
def parse_value(text: str) -> Any:
    """A ``--set`` value: JSON if it parses, else the text itself as a string."""
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def parse_assignment(text: str) -> tuple[str, Any]:
    """``KEY=VALUE`` -> ``(key, parsed value)``."""
    key, sep, value = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise OverrideError(f"--set takes KEY=VALUE, got {text!r}")
    return key, parse_value(value.strip())


def type_name(hint: Any) -> str:
    """A readable spelling of a type annotation."""
    if hint is _MISSING or hint is typing.Any:
        return "any"
    if hint is type(None):
        return "None"
    if isinstance(hint, type) and not typing.get_args(hint):
        return hint.__name__
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return " | ".join(type_name(arm) for arm in typing.get_args(hint))
    return str(hint).replace("typing.", "").replace("NoneType", "None")


def coerce(value: Any, hint: Any, key: str) -> Any:
    """``value`` as the type ``hint`` (int -> float, list -> tuple); ``OverrideError`` naming
    ``key`` when it does not fit."""
    result = _coerce(value, hint)
    if result is _MISSING:
        shown = json.dumps(value) if _jsonable(value) else repr(value)
        raise OverrideError(f"{key}: {shown} is not a {type_name(hint)}")
    return result


def _jsonable(value: Any) -> bool:
    try:
        json.dumps(value)
    except (TypeError, ValueError):
        return False
    return True


def _coerce(value: Any, hint: Any) -> Any:  # noqa: PLR0911, PLR0912 - one case per kind of type
    if hint is _MISSING or hint is typing.Any:
        return value
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is type(None) or hint is None:
        return None if value is None else _MISSING
    if origin in (typing.Union, types.UnionType):
        for arm in args:
            result = _coerce(value, arm)
            if result is not _MISSING:
                return result
        return _MISSING
    if origin is typing.Literal:
        for allowed in args:
            if type(value) is type(allowed) and value == allowed:
                return value
        return _MISSING
    if origin in (tuple, list):
        if not isinstance(value, list | tuple):
            return _MISSING
        if origin is list or (len(args) == 2 and args[1] is Ellipsis):
            item = args[0] if args else typing.Any
            items = [_coerce(v, item) for v in value]
        else:
            if len(args) != len(value):
                return _MISSING
            items = [_coerce(v, arm) for v, arm in zip(value, args, strict=True)]
        if any(v is _MISSING for v in items):
            return _MISSING
        return tuple(items) if origin is tuple else items
    if hint is bool:
        return value if isinstance(value, bool) else _MISSING
    if hint is int:
        return value if isinstance(value, int) and not isinstance(value, bool) else _MISSING
    if hint is float:
        if isinstance(value, int | float) and not isinstance(value, bool):
            return float(value) if not math.isnan(value) else _MISSING
        return _MISSING
    if hint is str:
        return value if isinstance(value, str) else _MISSING
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        return _MISSING  # a whole sub-config: set its fields one by one
    if isinstance(hint, type):
        return value if isinstance(value, hint) else _MISSING
    return _MISSING


# ---------------------------------------------------------------------------- env arguments
def _load(path: str) -> Any:
    module, _, attribute = path.partition(":")
    return getattr(importlib.import_module(module), attribute)


def _env_class(env_id: str) -> type:
    entry = gym.spec(env_id).entry_point
    env_class = _load(entry) if isinstance(entry, str) else entry
    if not isinstance(env_class, type):
        raise ValueError(f"{env_id}'s entry point is not a class: {entry!r}")
    return env_class


@cache
def _env_signature(env_id: str) -> tuple[tuple[str, Any, Any], ...]:
    env_class = _env_class(env_id)
    found: dict[str, tuple[Any, Any]] = {}
    for cls in reversed(env_class.__mro__):
        init = vars(cls).get("__init__")
        if init is None or cls.__module__.startswith(("gymnasium", "builtins")):
            continue
        try:
            hints = typing.get_type_hints(init)
        except Exception:  # noqa: BLE001 - an unresolvable annotation: fall back to defaults
            hints = {}
        for parameter in inspect.signature(init).parameters.values():
            if parameter.name == "self" or parameter.kind in (
                parameter.VAR_KEYWORD,
                parameter.VAR_POSITIONAL,
            ):
                continue
            default = parameter.default if parameter.default is not parameter.empty else _MISSING
            hint = hints.get(parameter.name, _MISSING)
            if hint is _MISSING and default is not _MISSING and default is not None:
                hint = type(default)
            found[parameter.name] = (hint, default)
    skip = set(FIXED_ENV_ARGUMENTS) | set(RENDER_ENV_ARGUMENTS)
    return tuple((name, h, d) for name, (h, d) in found.items() if name not in skip)


def _plain(value: Any) -> Any:
    """A JSON-ready copy (arrays and tuples as lists, NumPy scalars as Python numbers)."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if callable(value):  # a config's factory (HierarchicalConfig.extra_tasks): its name
        return f"{getattr(value, '__module__', '?')}.{getattr(value, '__qualname__', value)}"
    return value


@cache
def _task_goal(env_id: str) -> tuple[tuple[float, ...], bool]:
    """The goal the task class sets by default and whether the robot is planar (read back from
    an env: the task classes set the goal in their constructors, where no signature shows it)."""
    env = gym.make(env_id)
    try:
        base = wip_env(env)
        return tuple(float(v) for v in base.goal), bool(base.robot.layout.planar)
    finally:
        env.close()


def is_planar(env_id: str) -> bool:
    """Whether ``env_id``'s robot moves in the x-z plane (its goal is one number)."""
    return _task_goal(env_id)[1]


def env_settings(env_id: str) -> dict[str, Setting]:
    """Every ``env.<argument>`` key of ``env_id`` with its type, default and description (the
    env class's ``## Arguments`` table)."""
    docs = env_argument_docs(_env_class(env_id))
    settings = {}
    for name, hint, default in _env_signature(env_id):
        if name == "goal":
            goal, planar = _task_goal(env_id)
            default = goal[0] if planar else list(goal)
        key = f"env.{name}"
        settings[key] = Setting(key, hint, _plain(default), docs.get(name, ""))
    return settings


# ---------------------------------------------------------------------------- config dataclasses
def _is_instance(value: Any) -> bool:
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def _field_hints(config: Any) -> dict[str, Any]:
    try:
        return typing.get_type_hints(type(config))
    except Exception:  # noqa: BLE001 - fall back to the types of the values
        return {f.name: type(getattr(config, f.name)) for f in dataclasses.fields(config)}


def config_settings(config: Any, prefix: str) -> dict[str, Setting]:
    """Every leaf field of a (nested) config dataclass as ``prefix.dotted.path``, described by
    the ``Attributes:`` entry of the dataclass that declares it."""
    settings: dict[str, Setting] = {}
    hints = _field_hints(config)
    for field in dataclasses.fields(config):
        value = getattr(config, field.name)
        key = f"{prefix}.{field.name}"
        if _is_instance(value):
            settings.update(config_settings(value, key))
        else:
            description = field.metadata.get("doc") or config_field_doc(type(config), field.name)
            settings[key] = Setting(
                key, hints.get(field.name, type(value)), _plain(value), description
            )
    return settings


def _plan_class() -> type:
    from controllers.high_level.planning import PlanConfig

    return PlanConfig


def plan_configs(config: Any, path: str = "") -> list[str]:
    """The dotted paths of every ``PlanConfig`` inside ``config`` ("" when it is one)."""
    if isinstance(config, _plan_class()):
        return [path]
    found = []
    for field in dataclasses.fields(config):
        value = getattr(config, field.name)
        if _is_instance(value):
            found += plan_configs(value, f"{path}.{field.name}" if path else field.name)
    return found


def replace_path(config: Any, path: list[str], value: Any, key: str) -> Any:
    """``config`` with the field at ``path`` set to ``value`` (type-checked), as new frozen
    dataclasses all the way down."""
    name, rest = path[0], path[1:]
    names = [f.name for f in dataclasses.fields(config)]
    if name not in names:
        raise OverrideError(
            f"unknown key {key!r}: {type(config).__name__} has no field {name!r}; "
            f"its fields: {names}"
        )
    current = getattr(config, name)
    if rest:
        if not _is_instance(current):
            raise OverrideError(f"unknown key {key!r}: {name!r} is a value, not a config")
        new = replace_path(current, rest, value, key)
    else:
        if _is_instance(current):
            raise OverrideError(
                f"{key} is a whole {type(current).__name__}: set its fields, e.g. "
                f"{key}.{dataclasses.fields(current)[0].name}=..."
            )
        new = coerce(value, _field_hints(config).get(name, type(current)), key)
    try:
        return dataclasses.replace(config, **{name: new})
    except (TypeError, ValueError) as error:
        raise OverrideError(f"{key}={value!r}: {error}") from None


def apply_to_plans(config: Any, path: list[str], value: Any, key: str) -> Any:
    """``config`` with ``path`` set inside every ``PlanConfig`` it holds."""
    for plan_path in plan_configs(config):
        full = (plan_path.split(".") if plan_path else []) + path
        config = replace_path(config, full, value, key)
    return config


def config_dict(config: Any) -> dict[str, Any]:
    """A resolved config as a JSON-ready dict (nested configs as nested dicts)."""
    return _plain(config)


# ---------------------------------------------------------------------------- one run's settings
@dataclass(frozen=True)
class RunSpec:
    """Everything a run resolved from its defaults, preset, named flags and ``--set``.

    Attributes:
        env_id: the registered env. env_kwargs: the arguments passed to ``gym.make`` (those
            the preset, the flags and the overrides set; the rest are the env's defaults).
        configs: controller name -> its resolved config dataclass, in run order.
        preset: the preset's name (composed presets joined by commas) or None.
        overrides: the ``--set`` keys and parsed values.
        skipped: preset env arguments this env does not accept (logged, not applied).
        not_applied: ``plan.*`` key -> the controllers of the run it leaves as they are (they
            have no offline plan; :func:`keys_not_applied`).
    """

    env_id: str
    env_kwargs: dict[str, Any]
    configs: dict[str, Any]
    preset: str | None
    overrides: dict[str, Any]
    skipped: tuple[str, ...] = ()
    not_applied: dict[str, tuple[str, ...]] = dataclasses.field(default_factory=dict)

    def env_arguments(self) -> dict[str, Any]:
        """Every env argument in effect: the defaults updated with ``env_kwargs``."""
        effective = {k[len("env.") :]: s.default for k, s in env_settings(self.env_id).items()}
        effective.update(_plain(self.env_kwargs))
        return effective


def keys_not_applied(configs: Mapping[str, Any], keys: Iterable[str]) -> dict[str, tuple[str, ...]]:
    """The rule shared by compare and the sweep: a ``plan.*`` key applies to every controller
    of the run that has an offline plan and leaves the others as they are. This maps each such
    key to the controllers (of ``configs``) it leaves; keys that reach every controller are
    absent."""
    without_plan = tuple(name for name, config in configs.items() if not plan_configs(config))
    if not without_plan:
        return {}
    return {key: without_plan for key in keys if key.startswith("plan.")}


def valid_settings(env_id: str, configs: Mapping[str, Any]) -> dict[str, Setting]:
    """Every key of a run on ``env_id`` with these controllers' configs."""
    settings = dict(env_settings(env_id))
    plan_fields: dict[str, Setting] = {}
    for config in configs.values():
        for plan_path in plan_configs(config):
            plan = config
            for part in plan_path.split(".") if plan_path else []:
                plan = getattr(plan, part)
            for key, setting in config_settings(plan, "plan").items():
                plan_fields.setdefault(key, setting)
    settings.update(plan_fields)
    for name, config in configs.items():
        settings.update(config_settings(config, name))
    return settings


def _apply(
    key: str,
    value: Any,
    env_id: str,
    env_kwargs: dict[str, Any],
    configs: dict[str, Any],
    other_controllers: Iterable[str] = (),
) -> None:
    head, _, rest = key.partition(".")
    if not rest:
        raise OverrideError(
            f"unknown key {key!r}: keys are env.<argument>, plan.<field> or "
            f"<controller>.<field> (see --list-keys)"
        )
    if head == "env":
        settings = env_settings(env_id)
        if key not in settings:
            raise OverrideError(
                f"unknown key {key!r}: {env_id} has no argument {rest!r}; valid: "
                f"{sorted(s[len('env.') :] for s in settings)}"
            )
        env_kwargs[rest] = coerce(value, settings[key].type, key)
    elif head == "plan":  # every controller with a plan; the others unchanged (RunSpec)
        if not any(plan_configs(c) for c in configs.values()):
            raise OverrideError(f"{key}: no controller of this run has an offline plan")
        for name in configs:
            configs[name] = apply_to_plans(configs[name], rest.split("."), value, key)
    elif head in configs:
        configs[head] = replace_path(configs[head], rest.split("."), value, key)
    elif head in other_controllers:
        return  # a key for a controller that is not in this run (sweeps share one mapping)
    else:
        valid = ["env", "plan", *configs]
        raise OverrideError(
            f"unknown key {key!r}: {head!r} is not env, plan or a controller of this run; "
            f"valid prefixes: {valid}"
        )


def resolve_run(
    env_id: str,
    controllers: Iterable[str],
    preset: str | Sequence[str] | None = None,
    env_flags: Mapping[str, Any] | None = None,
    controller_flags: Mapping[str, Any] | None = None,
    overrides: Mapping[str, Any] | None = None,
    ignore_other_controllers: bool = False,
) -> RunSpec:
    """Resolve a run: defaults, then ``preset`` (one name or several composed in order,
    ``benchmarks.presets``), then the named flags (``env_flags``: env
    arguments; ``controller_flags``: fields set on every controller's config, e.g.
    ``model``), then ``overrides`` (``--set`` keys and parsed values, in order). Raises
    ``OverrideError`` naming the first bad key."""
    names = list(controllers)
    preset = presets.canonical(preset)
    preset_env, skipped = presets.env_arguments(preset, env_id, env_settings(env_id))
    controller_preset = presets.controller_preset(preset)
    configs = {name: registry.default_config(name, preset=controller_preset) for name in names}
    env_kwargs: dict[str, Any] = dict(preset_env)
    settings = env_settings(env_id)
    for name, value in (env_flags or {}).items():
        env_kwargs[name] = coerce(value, settings[f"env.{name}"].type, f"env.{name}")
    for field_name, value in (controller_flags or {}).items():
        for name in names:
            configs[name] = replace_path(configs[name], [field_name], value, f"{name}.{field_name}")
    others = registry.controller_names() if ignore_other_controllers else ()
    parsed = dict(overrides or {})
    for key, value in parsed.items():
        _apply(key, value, env_id, env_kwargs, configs, others)
    return RunSpec(
        env_id=env_id,
        env_kwargs=env_kwargs,
        configs=configs,
        preset=preset,
        overrides=_plain(parsed),
        skipped=tuple(skipped),
        not_applied=keys_not_applied(configs, parsed),
    )


def format_keys(settings: Mapping[str, Setting]) -> str:
    """The ``--list-keys`` table: key, type, default, then the description on the same line."""
    rows = [
        (s.key, type_name(s.type), json.dumps(s.default), s.description) for s in settings.values()
    ]
    width = max(len(r[0]) for r in rows) + 2
    type_width = max(len(r[1]) for r in rows) + 2
    default_width = min(24, max(len(r[2]) for r in rows))
    return "\n".join(
        f"{k:<{width}}{t:<{type_width}}{d:<{default_width}}  {text}".rstrip()
        for k, t, d, text in rows
    )
