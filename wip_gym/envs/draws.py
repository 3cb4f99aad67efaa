"""Random draws taken a block at a time (docs/realism.md §1): one call of a NumPy generator
costs microseconds, as much as an env step's own work, so the perturbations draw their
per-step numbers in blocks and hand them out one row per step."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np


class Draws:
    """Draws from ``rng`` taken ``block`` at a time, handed out one row per call;
    ``draw(rng, n)`` makes a block of ``n`` rows. Deterministic for a given stream and
    sequence of calls."""

    def __init__(
        self,
        rng: np.random.Generator,
        draw: Callable[[np.random.Generator, int], np.ndarray],
        block: int = 1024,
    ) -> None:
        self._rng, self._draw, self._block = rng, draw, block
        self._rows: list[Any] = []
        self._next = 0

    def __call__(self) -> Any:
        if self._next == len(self._rows):
            self._rows = self._draw(self._rng, self._block).tolist()
            self._next = 0
        row = self._rows[self._next]
        self._next += 1
        return row
