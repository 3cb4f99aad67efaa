"""Intervals of the sweep's report: Newcombe's
interval of a paired difference of success rates, Student's t interval of a paired mean
difference."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy import stats

from benchmarks.statistics import WILSON_Z, describe, rate, wilson_interval

__all__ = [
    "describe",
    "paired_mean_difference",
    "paired_success_difference",
    "rate",
    "wilson_interval",
]

Z95 = WILSON_Z  # the two-sided 95 % normal quantile


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
