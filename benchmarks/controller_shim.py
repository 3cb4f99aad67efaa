"""Adapter to the controller registry: ``controllers.registry`` when it exists, else a local
stand-in over ``benchmarks.registry`` with the same three functions.

    controller_names() -> list[str]
    default_config(name, preset=None) -> the controller's frozen config dataclass
    make_policy(name, env, config) -> the policy, built with that config

Delete this module (and import ``controllers.registry`` directly) once the registry is merged.
"""

from __future__ import annotations

import importlib
import warnings
from typing import Any

import gymnasium as gym

PRESETS = ("paper",)

try:  # the controllers' own registry (configs with .paper(), policy counters)
    from controllers.registry import controller_names as _names
    from controllers.registry import default_config as _default_config
    from controllers.registry import make_policy as _make_policy

    HAVE_REGISTRY = True
except ImportError:  # pragma: no cover - exercised until the registry lands
    HAVE_REGISTRY = False


def _load(path: str) -> Any:
    module, _, attribute = path.partition(":")
    return getattr(importlib.import_module(module), attribute)


def controller_names() -> list[str]:
    if HAVE_REGISTRY:
        return list(_names())
    from benchmarks.registry import controller_names as names

    return names()


def default_config(name: str, preset: str | None = None) -> Any:
    """The config of controller ``name``: its defaults, or the preset's constructor."""
    if preset is not None and preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r}; valid: {list(PRESETS)}")
    if HAVE_REGISTRY:
        return _default_config(name, preset=preset)
    from benchmarks.registry import _REGISTRY

    if name not in _REGISTRY:
        raise ValueError(f"unknown controller {name!r}; valid: {controller_names()}")
    _, config_path, fields = _REGISTRY[name]
    config_class = _load(config_path)
    if preset == "paper":
        if hasattr(config_class, "paper"):
            return config_class.paper(**fields)
        warnings.warn(
            f"{config_class.__name__} has no .paper() yet: controller {name!r} runs its defaults "
            "under --preset paper",
            stacklevel=2,
        )
    return config_class(**fields)


def make_policy(name: str, env: gym.Env, config: Any) -> Any:
    """The policy of controller ``name`` for ``env`` with ``config`` (already resolved)."""
    if HAVE_REGISTRY:
        return _make_policy(name, env, config)
    from benchmarks.registry import _REGISTRY

    if name not in _REGISTRY:
        raise ValueError(f"unknown controller {name!r}; valid: {controller_names()}")
    return _load(_REGISTRY[name][0]).for_env(env, config)


def policy_counters(policy: Any) -> dict[str, float]:
    """``policy.counters`` when the controller provides it; until then, the counts the
    controllers keep today, read from their attributes (QP failures, MPC rejections, the
    plan's violations and convergence)."""
    counters = getattr(policy, "counters", None)
    if counters is not None:
        return {str(k): float(v) for k, v in dict(counters).items()}
    found: dict[str, float] = {}
    qp = getattr(policy, "qp", None)
    if qp is not None and hasattr(qp, "failures"):
        found["qp_failures"] = float(qp.failures)
    high_level = getattr(policy, "high_level", None)
    mpc = getattr(high_level, "mpc", None)
    if mpc is not None and hasattr(mpc, "rejected"):
        found["mpc_rejections"] = float(mpc.rejected)
    plan = getattr(policy, "plan", None)
    if plan is not None and hasattr(plan, "violations"):
        found["plan_violations"] = float(len(plan.violations))
        found["plan_converged"] = float(bool(plan.converged))
    return found
