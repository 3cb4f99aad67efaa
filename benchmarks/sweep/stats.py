"""Intervals of the sweep's report: Wilson's score interval of a success rate, Newcombe's
interval of a paired difference of success rates, Student's t interval of a paired mean
difference."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy import stats

Z95 = float(stats.norm.ppf(0.975))


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson's score interval of a binomial proportion (Wilson 1927; Newcombe 1998, method 3).
    ValueError for n < 1 or successes outside [0, n]."""
    if n < 1 or not 0 <= successes <= n:
        raise ValueError(f"need 0 <= successes <= n and n >= 1, got {successes} of {n}")
    p = successes / n
    denominator = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denominator
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denominator
    # at p = 0 (p = 1) the lower (upper) end is exactly 0 (1); round-off would put it inside
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == n else min(1.0, centre + half)
    return low, high


def paired_success_difference(
    a: Sequence[bool], b: Sequence[bool], z: float = Z95
) -> tuple[float, tuple[float, float]]:
    """Rate of ``a`` minus rate of ``b`` over the same episodes, with Newcombe's (1998)
    interval for paired proportions (his method 10: Wilson intervals of both rates combined
    through the phi coefficient of the pairs; phi = 0 when a margin is empty)."""
    if len(a) != len(b) or not a:
        raise ValueError(f"need two equally long non-empty sequences, got {len(a)} and {len(b)}")
    both = sum(1 for x, y in zip(a, b, strict=True) if x and y)
    only_a = sum(1 for x, y in zip(a, b, strict=True) if x and not y)
    only_b = sum(1 for x, y in zip(a, b, strict=True) if y and not x)
    neither = len(a) - both - only_a - only_b
    n = len(a)
    p1, p2 = (both + only_a) / n, (both + only_b) / n
    l1, u1 = wilson_interval(both + only_a, n, z)
    l2, u2 = wilson_interval(both + only_b, n, z)
    margins = (both + only_a) * (only_b + neither) * (both + only_b) * (only_a + neither)
    phi = 0.0 if margins == 0 else (both * neither - only_a * only_b) / math.sqrt(margins)
    estimate = p1 - p2
    below = math.sqrt(max(0.0, (p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2))
    above = math.sqrt(max(0.0, (u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2))
    return estimate, (max(-1.0, estimate - below), min(1.0, estimate + above))


def paired_mean_difference(
    a: Sequence[float], b: Sequence[float], level: float = 0.95
) -> tuple[float, tuple[float, float] | None]:
    """Mean of ``a - b`` over pairs, with Student's t interval (None for fewer than 2 pairs)."""
    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    if d.size == 0:
        raise ValueError("no pairs")
    mean = float(d.mean())
    if d.size < 2:
        return mean, None
    half = float(stats.t.ppf(0.5 + level / 2, d.size - 1) * d.std(ddof=1) / math.sqrt(d.size))
    return mean, (mean - half, mean + half)


def describe(values: Sequence[float]) -> dict[str, float | int] | None:
    """``{n, mean, std, min, max}`` (std with ddof 1; 0 for one value); None if empty."""
    if not values:
        return None
    v = np.asarray(values, dtype=float)
    return {
        "n": int(v.size),
        "mean": float(v.mean()),
        "std": float(v.std(ddof=1)) if v.size > 1 else 0.0,
        "min": float(v.min()),
        "max": float(v.max()),
    }
