"""Summary statistics over episodes: every metric with its spread, every rate with an interval.

The one module of summary statistics: ``compare`` and the sweep's report both use it.
``describe`` gives ``{"mean", "std", "min", "max", "n"}`` (the sample standard deviation,
``ddof = 1``; 0 for one episode) of the episodes that report the metric; ``rate`` gives the
fraction of ``True`` among the episodes that report a boolean with its Wilson score 95 % interval
(Wilson 1927, the interval that stays inside [0, 1] and is not degenerate at 0 or n successes).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

WILSON_Z = 1.959963984540054  # the two-sided 95 % normal quantile


def describe(values: Sequence[float | int | None]) -> dict[str, float | int] | None:
    """Mean, standard deviation, minimum and maximum of the values present (None: absent);
    None when no episode reports the metric. Raises ``ValueError`` on a NaN."""
    present = np.array([v for v in values if v is not None], dtype=float)
    if present.size == 0:
        return None
    if np.isnan(present).any():
        raise ValueError(f"a metric has a NaN among its values {present.tolist()}")
    return {
        "mean": float(present.mean()),
        "std": float(present.std(ddof=1)) if present.size > 1 else 0.0,
        "min": float(present.min()),
        "max": float(present.max()),
        "n": int(present.size),
    }


def wilson_interval(successes: int, trials: int, z: float = WILSON_Z) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion ``successes / trials``."""
    if trials <= 0 or not 0 <= successes <= trials:
        raise ValueError(f"need 0 <= successes <= trials and trials > 0, got {successes}/{trials}")
    p = successes / trials
    denominator = 1.0 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denominator
    half = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / denominator
    # at 0 (all) successes the lower (upper) end is exactly 0 (1); round-off would put it inside
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == trials else min(1.0, centre + half)
    return low, high


def rate(values: Sequence[bool | None]) -> dict[str, Any] | None:
    """``{"rate", "ci95": [low, high], "n"}`` over the episodes that report the flag; None when
    none does."""
    present = [bool(v) for v in values if v is not None]
    if not present:
        return None
    successes = sum(present)
    low, high = wilson_interval(successes, len(present))
    return {"rate": successes / len(present), "ci95": [low, high], "n": len(present)}
