"""Which override keys a sweep may set, and which values they take.

The keys are exactly those of ``wip-bench compare --set`` (:mod:`benchmarks.overrides`):
``env.<argument>``, ``plan.<field>`` (every controller's offline plan) and
``<controller>.<dotted path>``. The sweep asks the same resolver the episode runner uses, so a
spec that validates is a spec that runs: each episode resolves the spec's keys for the sweep's
whole list of controllers, as compare resolves its run, and takes its own controller's config.
So a ``plan.*`` key leaves a controller without an offline plan as it is, in a sweep as in
compare (:func:`keys_not_applied`; the dry run and the report say so).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any

from benchmarks import overrides, presets
from controllers import registry

if TYPE_CHECKING:
    from benchmarks.sweep.spec import SweepSpec


def _resolve(key: str, value: Any, env_id: str, controllers: Sequence[str], preset: Any) -> None:
    overrides.resolve_run(env_id, list(controllers), preset=preset, overrides={key: value})


def validate_key(
    key: str, env_id: str, controllers: Sequence[str], preset: str | None = None
) -> None:
    """ValueError naming ``key`` (and the valid choices) unless a sweep of ``controllers`` on
    ``env_id`` may set it."""
    head, dot, rest = key.partition(".")
    if not dot or not rest:
        raise ValueError(
            f"unknown key {key!r}: expected env.<argument>, plan.<field> or <controller>.<path>"
        )
    controller_preset = presets.controller_preset(preset)
    configs = {name: registry.default_config(name, controller_preset) for name in controllers}
    settings = overrides.valid_settings(env_id, configs)
    if key not in settings:
        if head not in ("env", "plan", *controllers):
            raise ValueError(
                f"unknown key {key!r}: {head!r} is neither env, plan nor one of the sweep's "
                f"controllers {list(controllers)}"
            )
        near = sorted(k for k in settings if k.startswith(f"{head}."))
        if head == "plan" and not near:  # compare's words for the same refusal
            raise ValueError(f"{key}: no controller of this run has an offline plan")
        raise ValueError(f"unknown key {key!r}: no such setting; valid: {near}")


def validate_value(
    key: str, value: Any, env_id: str, controllers: Sequence[str], preset: str | None = None
) -> None:
    """ValueError naming ``key`` unless ``value`` has the key's type (the resolver's check)."""
    validate_key(key, env_id, controllers, preset)
    _resolve(key, value, env_id, controllers, preset)


PRESETS: tuple[str, ...] = presets.PRESET_NAMES


def validate_preset(preset: str | None, env_id: str) -> None:
    """ValueError naming ``preset`` unless the episode runner has it (None: no preset; several
    names joined by commas compose, ``benchmarks.presets``)."""
    try:
        presets.preset_names(preset)
    except ValueError as error:
        raise ValueError(f"{error} (for {env_id})") from None


def keys_not_applied(
    controllers: Sequence[str], preset: str | None, keys: Iterable[str]
) -> dict[str, tuple[str, ...]]:
    """The ``plan.*`` keys among ``keys`` and the controllers they leave as they are (no
    offline plan): ``benchmarks.overrides.keys_not_applied`` of the sweep's controllers."""
    configs = {
        name: registry.default_config(name, presets.controller_preset(preset))
        for name in controllers
    }
    return overrides.keys_not_applied(configs, keys)


def spec_keys_not_applied(spec: SweepSpec) -> dict[str, tuple[str, ...]]:
    """:func:`keys_not_applied` of a spec's ``[set]``, ``[grid]`` and ``[random]`` keys."""
    return keys_not_applied(spec.controllers, spec.preset, [*spec.base, *spec.grid, *spec.random])
