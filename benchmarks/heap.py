"""The objects made before a timed loop held out of the cyclic garbage collector's passes.

A closed-loop episode starts in a process that holds a few hundred thousand objects (JAX's,
numba's, MuJoCo's bindings, the env, the policy and its plan). The collector's full pass (its
oldest generation) walks all of them: 131 ms here, at a time set by the allocation counts,
so now inside an episode's timed loop, now outside it (the median of 7 full passes over a
``wip-bench`` process with KrangTray-v0 and ``unified`` reset). One such pause in an 8 s
episode adds about 2 units to its mean control step, and it came and went between two
revisions whose timed code was the same.

:func:`setup_frozen` moves the objects that exist when it starts to the permanent generation
(``gc.freeze``) for the loop, so that a pass walks only what the loop itself made; on exit they
go back (``gc.unfreeze``) and are collected as before. Nothing is switched off: the collector
runs at its usual thresholds, and garbage the loop makes is collected in the loop. A researcher's
own real-time loop can do the same. :class:`CollectorPasses` records the passes inside a block
(``wip-bench profile`` reports those of its loop).
"""

from __future__ import annotations

import gc
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from typing import Any

_depth = 0  # setup_frozen blocks open in this process


@contextmanager
def setup_frozen() -> Iterator[None]:
    """Freeze the objects that exist now for the ``with`` block (module docstring). Nested in
    another ``setup_frozen``, it freezes what was made since and leaves the thawing to the
    outermost one. The collector's permanent generation is one per process: the outermost
    block's exit thaws every freeze, a ``gc.freeze()`` made before it and another thread's
    included (they lose the benefit; nothing is lost)."""
    global _depth
    gc.freeze()
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
        if _depth == 0:
            gc.unfreeze()


class CollectorPasses:
    """The collector's passes that start while it is in use (``with CollectorPasses() as p``,
    through ``gc.callbacks``): :attr:`passes` holds ``(generation, seconds)`` of each."""

    def __init__(self) -> None:
        self.passes: list[tuple[int, float]] = []
        self._start: float | None = None

    def __call__(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            self._start = time.perf_counter()
        elif self._start is not None:
            self.passes.append((int(info["generation"]), time.perf_counter() - self._start))
            self._start = None

    def __enter__(self) -> CollectorPasses:
        gc.callbacks.append(self)
        return self

    def __exit__(self, *exc: object) -> None:
        with suppress(ValueError):  # gone if someone cleared gc.callbacks
            gc.callbacks.remove(self)

    def summary(self) -> dict[str, Any]:
        """``{"by_generation": [n0, n1, n2], "longest_ms": float, "total_ms": float}``."""
        pauses = [seconds * 1e3 for _, seconds in self.passes]
        return {
            "by_generation": [sum(g == k for g, _ in self.passes) for k in range(3)],
            "longest_ms": max(pauses, default=0.0),
            "total_ms": sum(pauses),
        }
