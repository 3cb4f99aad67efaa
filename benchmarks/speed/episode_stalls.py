"""The longest control steps of one ``wip-bench profile`` episode, part by part, and the garbage
collector's passes during the run: where a mean moved while its median did not.

    python -m benchmarks.speed.episode_stalls [--env wip_gym/KrangTray-v0]
                                              [--controller unified] [--duration 8]
    # another checkout's profiler (an older revision), run from this file:
    PYTHONPATH=<checkout> python <this checkout>/benchmarks/speed/episode_stalls.py

It runs ``wip-bench profile`` in this process (``benchmarks.cli.main``, so the heap is a
profile process's), with the profiler's part timers wrapped to keep every step's sample, and
times every collector pass through ``gc.callbacks``. Printed: per part, its mean, median, and
its largest sample with the step it fell on; then every full pass (the oldest generation) with
its duration, and the count of the younger ones. It uses only what the profiler has had since
docs/performance.md §12 (``_instrument`` and its timers' ``take``), so it runs on older
revisions too: docs/performance.md §20 found with it a 123 to 142 ms full pass at step 325 of
KrangTray-v0's episodes at the revisions of its table and of the one before (their profiler
has no freeze).
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
    args = parser.parse_args()
    if args.duration <= 0:
        parser.error("--duration must be positive")
    samples: dict[str, list[float]] = {}
    instrument = profile._instrument

    def keeping(policy: Any) -> Any:
        timers = instrument(policy)
        for name, timer in timers.items():
            kept = samples.setdefault(name, [])
            take = timer.take

            def take_and_keep(take: Any = take, kept: list[float] = kept) -> float:
                value = take()
                kept.append(value)
                return float(value)

            timer.take = take_and_keep
        return timers

    passes: list[tuple[int, float]] = []
    started = [0.0]

    def timed(phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            started[0] = time.perf_counter()
        else:
            passes.append((int(info["generation"]), time.perf_counter() - started[0]))

    profile._instrument = keeping
    gc.callbacks.append(timed)
    argv = ["profile", "--env", args.env, "--controller", args.controller]
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
    full = [seconds * 1e3 for generation, seconds in passes if generation == 2]
    younger = sum(generation < 2 for generation, _ in passes)
    print(f"collector: {younger} younger passes; full passes, ms: {[round(t, 1) for t in full]}")


if __name__ == "__main__":
    main()
