"""The longest control steps of one ``wip-bench profile`` episode, part by part, and the garbage
collector's passes during the run: where a mean moved while its median did not.

    python -m benchmarks.speed.episode_stalls [--env wip_gym/KrangTray-v0]
                                              [--controller unified] [--duration 8]
                                              [--no-freeze]
    # another checkout's profiler (an older revision), run from this file:
    PYTHONPATH=<checkout> python <this checkout>/benchmarks/speed/episode_stalls.py

It runs ``wip-bench profile`` in this process (``benchmarks.cli.main``, so the heap is a
profile process's), with the profiler's part timers wrapped to keep every step's sample, and
times every collector pass through ``gc.callbacks``. Printed: per part, its mean, median, and
its largest sample with the step it fell on; then every full pass (the oldest generation) with
its duration and the control step it fell in (or "outside the episode"), and the count of the
younger ones. ``--no-freeze`` is handed to the profile (a profiler that has the freeze,
``benchmarks.heap``; older ones have no freeze and no such flag). It uses only what the
profiler has had since docs/performance.md §12 (``_instrument`` and its timers' ``take``), so
it runs on older revisions too (docs/performance.md §20 has what it found there).
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import io
import time
from typing import Any

import numpy as np

from benchmarks import cli
from benchmarks.speed import profile


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="wip_gym/KrangTray-v0")
    parser.add_argument("--controller", default="unified")
    parser.add_argument("--duration", type=float, default=8.0)
    parser.add_argument("--no-freeze", action="store_true", help="handed to wip-bench profile")
    args = parser.parse_args()
    if args.duration <= 0:
        parser.error("--duration must be positive")
    samples: dict[str, list[float]] = {}
    instrument = profile._instrument

    def keeping(policy: Any) -> Any:
        timers = instrument(policy)
        samples.setdefault(first, [])
        for name, timer in timers.items():
            kept = samples.setdefault(name, [])
            take = timer.take

            def take_and_keep(take: Any = take, kept: list[float] = kept) -> float:
                value = take()
                kept.append(value)
                return float(value)

            timer.take = take_and_keep
        return timers

    # (generation, seconds, the steps taken when it ran: None before the loop's instrumentation)
    passes: list[tuple[int, float, int | None]] = []
    started = [0.0]
    first = "robot_model"  # a part every profiled controller has: one sample per step taken

    def timed(phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            started[0] = time.perf_counter()
            return
        seconds = time.perf_counter() - started[0]
        taken = len(samples[first]) if first in samples else None
        passes.append((int(info["generation"]), seconds, taken))

    profile._instrument = keeping
    gc.callbacks.append(timed)
    argv = ["profile", "--env", args.env, "--controller", args.controller]
    if args.no_freeze:
        argv.append("--no-freeze")
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            cli.main([*argv, "--duration", str(args.duration)])
    finally:
        gc.callbacks.remove(timed)
        profile._instrument = instrument
    print(f"{args.controller} on {args.env}, {args.duration} s (profile's own output hidden)")
    print("| part | mean us | median us | largest us | at step |")
    print("|---|---|---|---|---|")
    for name, values in samples.items():
        us = np.asarray(values) * 1e6
        print(
            f"| {name} | {us.mean():.1f} | {np.median(us):.1f} | {us.max():.0f} "
            f"| {int(us.argmax())} |"
        )
    steps = len(samples.get(first, []))

    def when(taken: int | None) -> str:
        if taken is None:
            return "before the loop"
        return f"in step {taken}" if taken < steps else "after the loop"

    full = [f"{seconds * 1e3:.1f} ms {when(taken)}" for g, seconds, taken in passes if g == 2]
    younger = sum(g < 2 for g, _, _ in passes)
    print(f"collector: {younger} younger passes; full passes: {'; '.join(full) or 'none'}")


if __name__ == "__main__":
    main()
