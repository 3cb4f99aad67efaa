"""What a sweep worker does with one episode: run it under a wall-clock limit and return its
store row, metrics or the error's traceback. Runs in the worker process; imports no Ray."""

from __future__ import annotations

import functools
import os
import signal
import socket
import subprocess
import time
import traceback
from collections.abc import Callable, Mapping
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

EpisodeFn = Callable[[Mapping[str, Any]], dict[str, Any]]


class EpisodeTimeout(Exception):
    """The episode outlived the sweep's wall-clock limit."""


@functools.cache
def provenance() -> dict[str, Any]:
    """The package version and git commit of the code this process runs (None outside a git
    checkout); ``git_dirty`` when it has uncommitted changes."""
    try:
        version: str | None = metadata.version("wip-gym")
    except metadata.PackageNotFoundError:
        version = None
    root = Path(__file__).resolve().parents[2]
    commit: str | None = None
    dirty: bool | None = None
    try:
        commit = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            check=True,
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
        status = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            check=True,
            capture_output=True,
            text=True,
            timeout=10,
        )
        dirty = bool(status.stdout.strip())
    except (OSError, subprocess.SubprocessError):
        pass
    return {"package_version": version, "git_commit": commit, "git_dirty": dirty}


def _raise_timeout(signum: int, frame: Any) -> None:
    raise EpisodeTimeout("the episode outlived the sweep's wall-clock limit")


def execute(job: Mapping[str, Any], episode_fn: EpisodeFn, timeout_s: float) -> dict[str, Any]:
    """The store row of ``job``: status ``ok`` with the metrics, or ``error`` with the
    traceback (an exception, or the wall-clock limit ``timeout_s``, raised in the episode by
    SIGALRM where the worker runs tasks on its main thread)."""
    start = time.perf_counter()
    use_alarm = hasattr(signal, "SIGALRM") and _on_main_thread()
    previous = None
    if use_alarm:
        previous = signal.signal(signal.SIGALRM, _raise_timeout)
        signal.setitimer(signal.ITIMER_REAL, timeout_s)
    metrics: dict[str, Any] | None = None
    error: str | None = None
    try:
        metrics = episode_fn(job)
    except Exception:  # any failure of one episode becomes its error row
        error = traceback.format_exc()
    finally:
        if use_alarm:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
    return finish_row(job, metrics, error, time.perf_counter() - start)


def _on_main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


def finish_row(
    job: Mapping[str, Any], metrics: dict[str, Any] | None, error: str | None, wall_s: float
) -> dict[str, Any]:
    """A store row: the job's identity and resolved parameters, then the outcome."""
    return {
        **job,
        "status": "ok" if error is None else "error",
        "error": error,
        "metrics": metrics,
        "wall_s": wall_s,
        "host": socket.gethostname(),
        "pid": os.getpid(),
        "finished_at": datetime.now(UTC).isoformat(timespec="seconds"),
        **provenance(),
    }
