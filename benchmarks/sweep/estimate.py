"""``wip-bench sweep --dry-run``'s time estimate, from speeds measured on the spec's own env.

Two sources, the first that applies:

* **the directory's rows**: the mean wall time of the episodes already finished in ``--out``;
* **calibration**: for each controller, one episode of :data:`CALIBRATION_S` simulated seconds
  (at most the spec's duration) on the spec's first cell and replicate (its ``[set]``, grid and
  ``[random]`` values, its seed), run in this process after a :data:`WARMUP_S` episode that
  loads what a sweep worker loads once (compiled code, caches). Its setup time and real-time
  factor give each of that controller's episodes ``setup_s + duration / real_time_factor``.

The estimate divides the total by the workers: it holds for workers with a core each, on a
machine as busy as it was while calibrating (the output gives the load average then). It leaves
out each worker's start (Ray, imports, the first compilation: some seconds per worker, once),
which matters for a sweep of a few episodes, not of hundreds. An episode that ends early (a fall
or a lost cup ends it) takes less, so where losses are common it is an upper bound.
"""

from __future__ import annotations

import os
import statistics
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from benchmarks.sweep.spec import Episode, SweepSpec
from benchmarks.sweep.store import read_rows

CALIBRATION_S = 2.0  # simulated seconds of the measured episode per controller
WARMUP_S = 0.01  # simulated seconds of the episode before it (its setup loads the caches)

EpisodeFn = Callable[..., dict[str, Any]]


@dataclass(frozen=True)
class Calibration:
    """One controller's measured speed on the spec's env."""

    controller: str
    setup_s: float  # env reset and the policy's reset (the offline plan)
    real_time_factor: float  # simulated seconds per wall second of the step loop
    sim_time_s: float  # simulated seconds it was measured over (less if the episode ended)
    error: str | None = None  # what the calibration episode raised (its times are then 0)

    def episode_s(self, duration: float) -> float:
        """The wall time of one episode of ``duration`` simulated seconds (0 for a controller
        whose calibration episode raised: its episodes fail at once)."""
        if self.error is not None:
            return 0.0
        return self.setup_s + duration / self.real_time_factor


def calibrate(spec: SweepSpec, episode_fn: EpisodeFn | None = None) -> list[Calibration]:
    """One measured episode per controller (see the module docstring); ``episode_fn`` is
    :func:`benchmarks.rollout.run_configured_episode` unless given (tests)."""
    if episode_fn is None:
        from benchmarks.rollout import run_configured_episode

        episode_fn = run_configured_episode
    seconds = min(CALIBRATION_S, spec.duration)
    first: dict[str, Episode] = {}
    for episode in spec.episodes():
        first.setdefault(episode.controller, episode)
    calibrations = []
    for controller in spec.controllers:
        e = first[controller]
        try:
            row = _measure(episode_fn, spec, controller, e, seconds)
        except Exception as error:  # noqa: BLE001 - the sweep reports it per episode too
            calibrations.append(
                Calibration(controller, 0.0, 1.0, 0.0, f"{type(error).__name__}: {error}")
            )
            continue
        calibrations.append(
            Calibration(
                controller,
                float(row["setup_s"]),
                float(row["real_time_factor"]),
                float(row["sim_time_s"]),
            )
        )
    return calibrations


def _measure(
    episode_fn: EpisodeFn, spec: SweepSpec, controller: str, e: Episode, seconds: float
) -> dict[str, Any]:
    """The calibration episode's row, after the warm-up episode."""
    row: dict[str, Any] = {}
    for duration in (WARMUP_S, seconds):
        row = episode_fn(
            spec.env,
            controller,
            e.parameters,
            e.seed,
            duration,
            preset=spec.preset,
            run_controllers=spec.controllers,  # a plan.* key may leave it as configured
        )
    return row


def from_calibration(
    spec: SweepSpec, todo: Sequence[Episode], calibrations: Sequence[Calibration], workers: int
) -> tuple[float, list[str]]:
    """Wall seconds of the ``todo`` episodes on ``workers``, and the lines that say how."""
    seconds = 0.0
    lines = [
        f"time estimate calibrated in this process: per controller one episode of up to "
        f"{min(CALIBRATION_S, spec.duration):g} s simulated on cell 0, replicate 0 (after a "
        f"{WARMUP_S:g} s warm-up episode; load average {os.getloadavg()[0]:.1f} on "
        f"{os.cpu_count()} CPUs):"
    ]
    for c in calibrations:
        count = sum(1 for e in todo if e.controller == c.controller)
        seconds += count * c.episode_s(spec.duration)
        if c.error is not None:
            lines.append(
                f"  {c.controller}: its calibration episode raised ({c.error}); its {count} "
                f"episodes are counted as taking no time"
            )
            continue
        lines.append(
            f"  {c.controller}: setup {c.setup_s:.2f} s, {c.real_time_factor:.1f} x real time "
            f"over {c.sim_time_s:g} s -> {c.episode_s(spec.duration):.2f} s per "
            f"{spec.duration:g} s episode, {count} episodes"
        )
    return seconds / max(1, workers), lines


def from_rows(todo: int, workers: int, directory: str) -> tuple[float, list[str]] | None:
    """Wall seconds of ``todo`` episodes from the mean wall time of the directory's finished
    episodes; None when it has none."""
    walls = [r["wall_s"] for r in read_rows(directory) if r.get("status") == "ok"]
    if not walls:
        return None
    per_episode = statistics.fmean(walls)
    line = (
        f"time estimate measured: mean {per_episode:.1f} s over {len(walls)} episodes in "
        f"{directory}"
    )
    return todo * per_episode / max(1, workers), [line]
