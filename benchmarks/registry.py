"""Controllers by benchmark name: a re-export of :mod:`controllers.registry`, the one registry.

``make_policy(name, env, model)`` keeps this module's older signature (the model choice as the
third argument) for the callers that use it; new code imports from ``controllers.registry``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from controllers.policy import ModelChoice, Policy
from controllers.registry import controller_names, default_config, register
from controllers.registry import make_policy as _make_policy

__all__ = ["controller_names", "default_config", "make_policy", "register"]


def make_policy(
    name: str, env: gym.Env, model: ModelChoice = "nominal", config: Any = None
) -> Policy:
    """``controllers.registry.make_policy(name, env, config, model)``."""
    return _make_policy(name, env, config, model)
