"""Episode seeds and identities from what an episode is, never from where it sits in a sweep.

An episode's seed is a hash of its env, preset, its cell's resolved parameters (the ``[set]``
overrides and the cell's grid values), its replicate and the sweep's seed: adding a value to an
axis, reordering axes, or running on another number of workers leaves every other episode's seed
unchanged. Every controller of a cell and replicate gets the same seed (and the same ``[random]``
draws), so controllers are compared on the same episodes (paired differences in the report).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from typing import Any

import numpy as np

SEED_BITS = 32  # seeds stay exact in any JSON reader and are valid everywhere a seed is taken


def canonical_json(value: Any) -> str:
    """One text per value: keys sorted, no whitespace, ints and floats kept apart (1 != 1.0)."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False)


def _digest(value: Any) -> bytes:
    return hashlib.sha256(canonical_json(value).encode()).digest()


def cell_seed(
    env_id: str,
    preset: str | None,
    parameters: Mapping[str, Any],
    replicate: int,
    sweep_seed: int,
) -> int:
    """The seed of replicate ``replicate`` of the cell with resolved ``parameters``."""
    payload = {
        "env": env_id,
        "preset": preset,
        "parameters": dict(parameters),
        "replicate": replicate,
        "sweep_seed": sweep_seed,
    }
    return int.from_bytes(_digest(payload)[: SEED_BITS // 8], "big")


def episode_id(
    env_id: str,
    preset: str | None,
    duration: float,
    parameters: Mapping[str, Any],
    random: Mapping[str, Any],
    controller: str,
    replicate: int,
    sweep_seed: int,
) -> str:
    """The store's key of one episode: everything that defines it (the random draws through
    their distributions and the seed)."""
    payload = {
        "env": env_id,
        "preset": preset,
        "duration": duration,
        "parameters": dict(parameters),
        "random": dict(random),
        "controller": controller,
        "replicate": replicate,
        "sweep_seed": sweep_seed,
    }
    return _digest(payload).hex()[:20]


def key_stream(seed: int, key: str) -> np.random.Generator:
    """The generator of ``key``'s ``[random]`` draw in the episode with ``seed``: one stream per
    key, so adding a random key does not change the others' draws, and none of them is the
    env's own reset stream (``env.reset(seed=seed)``)."""
    key_entropy = int.from_bytes(hashlib.sha256(key.encode()).digest()[:8], "big")
    return np.random.default_rng(np.random.SeedSequence([seed, key_entropy]))
