"""The control step's time by its place in the MPC period: where a delayed MPC costs the loop.

    python -m benchmarks.speed.mpc_phase [--env wip_gym/KrangTray-v0] [--delay 5]
        [--duration 8] [--seed 0]

One episode of ``unified`` with the MPC beside the loop (``mpc_delay_steps = --delay``), its
control steps grouped by ``step % steps_per_mpc``: phase 0 starts the solve in the background
thread, phase ``d`` takes its solution (and waits if the solve is not done). Each phase's mean,
median, p90 and p99 (us) and, for the episode, the solve's own time in its thread (median
and p90: from the call of ``ModelPredictiveController.run``, the compiled step, in the MPC's
thread to its return) and the control thread's wait for it at phase ``d``
(``HighLevel._wait_pending``, which also takes the solution into use:
``ModelPredictiveController.take``, its rows as Python floats). The first 100 steps (the
start) are left out of the phases. Times in microseconds of the machine it runs on: compare runs
of one process, or runs alternated with the same command (docs/performance.md §13).
"""

from __future__ import annotations

import argparse
import threading
import time
from collections.abc import Sequence
from typing import Any
from unittest import mock

import numpy as np

from benchmarks.overrides import resolve_run
from benchmarks.rollout import rollout
from controllers.high_level import mpc as mpc_module
from controllers.high_level.receding_horizon import MPC_THREAD, HighLevel
from controllers.optimizer import jax_setup

SKIPPED_STEPS = 100


def phase_table(control_times_s: np.ndarray, steps_per_mpc: int) -> list[dict[str, float]]:
    """Per phase ``step % steps_per_mpc`` (steps counted from 0, the first ``SKIPPED_STEPS``
    left out): mean, median, p90, p99 of the control times, in us."""
    if steps_per_mpc < 1:
        raise ValueError(f"steps_per_mpc must be >= 1, got {steps_per_mpc}")
    times = np.asarray(control_times_s, dtype=float)[SKIPPED_STEPS:] * 1e6
    if len(times) < steps_per_mpc:
        raise ValueError(
            f"too few control steps after the first {SKIPPED_STEPS}: {len(times)} "
            f"(need at least one per phase, {steps_per_mpc})"
        )
    phases = (np.arange(len(times)) + SKIPPED_STEPS) % steps_per_mpc
    rows = []
    for phase in range(steps_per_mpc):
        x = times[phases == phase]
        rows.append(
            {
                "phase": float(phase),
                "mean": float(x.mean()),
                "median": float(np.median(x)),
                "p90": float(np.percentile(x, 90)),
                "p99": float(np.percentile(x, 99)),
            }
        )
    return rows


def _median_p90(values_us: np.ndarray) -> dict[str, float]:
    return {"median": float(np.median(values_us)), "p90": float(np.percentile(values_us, 90))}


def run(env_id: str, delay: int, duration: float, seed: int) -> dict[str, Any]:
    """One episode (see the module docstring); the phase table, the solve's times in the MPC's
    thread and the control thread's waits for a solve (``HighLevel._wait_pending``), in us."""
    if delay < 1:
        raise ValueError(f"delay must be >= 1 (a solve beside the loop), got {delay}")
    overrides = {"unified.high_level.mpc_delay_steps": delay}
    spec = resolve_run(
        env_id, ["unified"], None, overrides=overrides, ignore_other_controllers=True
    )
    solves: list[float] = []
    waits: list[float] = []
    run_step, wait = mpc_module.ModelPredictiveController.run, HighLevel._wait_pending

    def timed_run(self: Any, *args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        result = run_step(self, *args, **kwargs)
        if threading.current_thread().name == MPC_THREAD:  # beside the loop
            solves.append(time.perf_counter() - start)
        return result

    def timed_wait(self: Any) -> None:
        start = time.perf_counter()
        wait(self)
        waits.append(time.perf_counter() - start)

    with (
        mock.patch.object(mpc_module.ModelPredictiveController, "run", timed_run),
        mock.patch.object(HighLevel, "_wait_pending", timed_wait),
    ):
        episode = rollout(
            env_id, spec.env_kwargs, "unified", spec.configs["unified"], seed, duration
        )
    if not solves or not waits:
        raise ValueError(
            f"no MPC solve ran beside the loop and was taken in {duration} s: run longer"
        )
    steps_per_mpc = episode.policy.high_level.steps_per_mpc
    solve_us, wait_us = np.asarray(solves) * 1e6, np.asarray(waits) * 1e6
    control = episode.control_times[SKIPPED_STEPS:]
    return {
        "phases": phase_table(episode.control_times, steps_per_mpc),
        "solve_us": _median_p90(solve_us),
        "wait_us": _median_p90(wait_us),
        "control_mean_us": float(control.mean() * 1e6),
        "control_p99_us": float(np.percentile(control, 99) * 1e6),
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="wip_gym/KrangTray-v0")
    parser.add_argument("--delay", type=int, default=5, help="mpc_delay_steps, >= 1")
    parser.add_argument("--duration", type=float, default=8.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    if args.duration <= 0:
        parser.error("--duration must be positive")
    if args.delay < 1:
        parser.error("--delay must be >= 1 (the MPC beside the loop)")
    jax_setup.configure()
    result = run(args.env, args.delay, args.duration, args.seed)
    print(f"unified on {args.env}, mpc_delay_steps = {args.delay}, seed {args.seed}")
    print("| phase | mean us | median us | p90 us | p99 us |")
    print("|---|---|---|---|---|")
    for row in result["phases"]:
        print(
            f"| {int(row['phase'])} | {row['mean']:.0f} | {row['median']:.0f} | "
            f"{row['p90']:.0f} | {row['p99']:.0f} |"
        )
    solve, waits = result["solve_us"], result["wait_us"]
    print(
        f"control mean {result['control_mean_us']:.0f} us, p99 {result['control_p99_us']:.0f} us; "
        f"the solve in its thread: median {solve['median']:.0f} us, p90 {solve['p90']:.0f} us; "
        f"the control step's wait for it: median {waits['median']:.0f} us, "
        f"p90 {waits['p90']:.0f} us"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
