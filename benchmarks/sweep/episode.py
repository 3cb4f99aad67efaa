"""The one place the sweep calls the episode runner.

``run_configured_episode(env_id, controller, overrides, seed, duration, preset,
run_controllers)`` returns one episode's JSON-ready metrics: the project's one rollout
(:mod:`benchmarks.rollout`), the same function ``wip-bench compare`` runs, so a sweep's metrics
are defined where compare's are, and its overrides resolved for the sweep's whole list of
controllers as compare resolves a run (:mod:`benchmarks.sweep.keys`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from benchmarks.rollout import run_configured_episode

__all__ = ["run_configured_episode", "run_episode_job"]


def run_episode_job(job: Mapping[str, Any]) -> dict[str, Any]:
    """Run the episode a job describes (see :func:`benchmarks.sweep.runner.make_job`)."""
    return run_configured_episode(
        job["env"],
        job["controller"],
        job["parameters"],
        job["seed"],
        job["duration"],
        preset=job["preset"],
        run_controllers=job["run_controllers"],
    )
