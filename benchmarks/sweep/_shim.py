"""Interim episode runner of the sweep, with the signature of the project's configured rollout
(``run_configured_episode``), built on :func:`benchmarks.episode.run_episode` and
:class:`benchmarks.scenario.Scenario`. :mod:`benchmarks.sweep.episode` is the one place that
imports it; the project's own rollout replaces it there.

Keys it handles: ``env.<argument>`` (any argument of the env's constructor: goal, cup friction,
push, payload through the scenario, the others such as ``mass_randomization`` as extra
``gym.make`` keyword arguments), ``plan.<field>`` (the offline plan inside the controller's config;
``plan.a_max`` also ``"cup_safe"`` or ``"none"``), ``<controller>.<dotted path>`` (this episode's
controller's config; keys of the sweep's other controllers are not this episode's and are
ignored). Anything else raises ValueError.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from benchmarks import registry
from benchmarks.episode import run_episode
from benchmarks.scenario import Push, Scenario
from benchmarks.sweep.keys import A_MAX_SPELLINGS, env_arguments

_SCENARIO_FIELDS = ("goal", "cup_friction", "payload_mass", "payload_time")
_PUSH_FIELDS = ("push_force", "push_time", "push_duration")


@dataclass(frozen=True)
class _SweepScenario(Scenario):
    """A scenario with more env arguments than :class:`Scenario` names."""

    extra_env: tuple[tuple[str, Any], ...] = ()

    def env_kwargs(self) -> dict[str, Any]:
        return {**super().env_kwargs(), **dict(self.extra_env)}

    def make_env(self, **extra: Any) -> gym.Env:
        return gym.make(self.env_id, max_episode_steps=None, **self.env_kwargs(), **extra)


def _replace_path(config: Any, path: list[str], value: Any, key: str) -> Any:
    if not dataclasses.is_dataclass(config):
        raise ValueError(f"cannot set {key!r}: {path[0]!r} is below a non-config field")
    names = [f.name for f in dataclasses.fields(config)]
    if path[0] not in names:
        raise ValueError(f"cannot set {key!r}: no field {path[0]!r}; valid: {names}")
    if len(path) == 1:
        new = tuple(value) if isinstance(value, list) else value
    else:
        new = _replace_path(getattr(config, path[0]), path[1:], value, key)
    return dataclasses.replace(config, **{path[0]: new})


def _plan_paths(config: Any, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Dotted paths of every PlanConfig inside a controller config."""
    from controllers.planning import PlanConfig

    paths = []
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if isinstance(value, PlanConfig):
            paths.append((*prefix, f.name))
        elif dataclasses.is_dataclass(value):
            paths.extend(_plan_paths(value, (*prefix, f.name)))
    return paths


def _controller_config(controller: str, overrides: Mapping[str, Any]) -> Any:
    if controller not in registry.controller_names():
        raise ValueError(f"unknown controller {controller!r}; valid: {registry.controller_names()}")
    _, config_path, fields = registry._REGISTRY[controller]
    config = registry._load(config_path)(**fields)
    plan_paths = _plan_paths(config)
    for key, value in overrides.items():
        scope, _, path = key.partition(".")
        if scope == "plan":
            if not plan_paths:
                raise ValueError(f"cannot set {key!r}: {controller} has no offline plan")
            if path == "a_max" and isinstance(value, str):
                value = A_MAX_SPELLINGS[value]
            for plan_path in plan_paths:
                config = _replace_path(config, [*plan_path, *path.split(".")], value, key)
        elif scope == controller:
            config = _replace_path(config, path.split("."), value, key)
    return config


def _scenario(env_id: str, overrides: Mapping[str, Any], duration: float, model: str) -> Scenario:
    arguments = env_arguments(env_id)
    named: dict[str, Any] = {}
    push: dict[str, Any] = {}
    extra: dict[str, Any] = {}
    for key, value in overrides.items():
        scope, _, name = key.partition(".")
        if scope != "env":
            continue
        if name not in arguments:
            raise ValueError(f"cannot set {key!r}: {env_id} has no argument {name!r}")
        if name in _SCENARIO_FIELDS:
            named[name] = value
        elif name in _PUSH_FIELDS:
            push[name] = value
        else:
            extra[name] = value
    if "goal" in named:
        goal = named["goal"]
        named["goal"] = tuple(goal) if isinstance(goal, list) else (goal,)
    if push:
        named["push"] = Push(
            float(push.get("push_force", arguments["push_force"])),
            float(push.get("push_time", arguments["push_time"])),
            float(push.get("push_duration", arguments["push_duration"])),
        )
    return _SweepScenario(
        env_id=env_id,
        duration=duration,
        model=model,
        extra_env=tuple(sorted(extra.items())),
        **named,
    )


def _json_ready(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _json_ready(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_ready(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def run_configured_episode(
    env_id: str,
    controller: str,
    overrides: Mapping[str, Any],
    seed: int,
    duration: float,
    preset: str | None = None,
) -> dict[str, Any]:
    """One episode of ``controller`` on ``env_id`` with ``overrides``; its metrics (JSON-ready)."""
    if preset is not None:
        raise ValueError(f"unknown preset {preset!r}: the interim episode runner has none")
    for key in overrides:
        scope, dot, path = key.partition(".")
        if not dot or not path or scope not in ("env", "plan", *registry.controller_names()):
            raise ValueError(f"cannot set {key!r}: expected env.*, plan.* or <controller>.*")
    config = _controller_config(controller, overrides)
    scenario = _scenario(env_id, overrides, duration, config.model)
    controller_path, config_path, _ = registry._REGISTRY[controller]
    fields = {f.name: getattr(config, f.name) for f in dataclasses.fields(config)}
    fields.pop("model")
    name = f"_sweep_{controller}"
    registry.register(name, controller_path, config_path, **fields)
    try:
        result = run_episode(scenario, name, seed)
    finally:
        registry._REGISTRY.pop(name, None)
    result["controller"] = controller
    return _json_ready({k: v for k, v in result.items() if not k.startswith("_")})
