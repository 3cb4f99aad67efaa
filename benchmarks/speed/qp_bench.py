"""The task-QP half of ``wip-bench solvers``: our ProxQP path against OSQP, DAQP, quadprog and
SLSQP on the QPs of a real closed loop.

For each env (``planar``: ``PlanarTray-v0``, ``krang``: ``KrangTray-v0``) the ``unified``
controller runs a short episode and every control step's QP is recorded
(:mod:`benchmarks.speed.qp_recording`). Each solver (:mod:`benchmarks.speed.qp_peers`) then solves
the same sequence in order (warm starts carry from one QP to the next, as in the controller), in
``passes`` passes, each from a fresh start. First the solutions: every one is compared with the
KKT-checked reference; a solver agrees when all of them are within
:data:`benchmarks.speed.qp_peers.SOLUTION_TOLERANCE` (a solver that does not is reported with its
worst error and its failures, never dropped and never given a looser test). Then the times:
the wall time of each ``solve`` call (ours: ProxQP's ``update`` + ``solve``; OSQP's ``update`` +
``solve``; the others' whole call), median and p99 in microseconds over all passes.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from tqdm import tqdm

from benchmarks.speed.qp_peers import (
    SOLUTION_TOLERANCE,
    QPSolver,
    all_solvers,
    reference_solution,
    solution_error,
)
from benchmarks.speed.qp_recording import Recording, record_qps

ENVS = {"planar": "wip_gym/PlanarTray-v0", "krang": "wip_gym/KrangTray-v0"}
ACTIVE_TOLERANCE = 1e-9


@dataclass(frozen=True)
class QPBenchConfig:
    """Attributes: seconds: closed-loop time recorded per env (one QP per 1 ms step).
    passes: timed passes over the sequence per solver. seed: the episode's reset seed."""

    seconds: float = 0.4
    passes: int = 3
    seed: int = 0


@contextlib.contextmanager
def _quiet_stdout() -> Iterator[None]:
    """Silence the C-level stdout (OSQP prints "Polishing not needed" from C whatever its
    ``verbose``); set once around a whole pass, not per timed call."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def _run_solver(
    solver: QPSolver, recording: Recording, references: list[np.ndarray], passes: int, label: str
) -> dict[str, Any]:
    times: list[float] = []
    errors: list[float] = []
    failures: list[str] = []
    for _ in tqdm(range(passes), desc=label, leave=False, disable=None):
        solver.start()
        with _quiet_stdout():
            for qp, x_ref in zip(recording.qps, references, strict=True):
                start = time.perf_counter()
                try:
                    x = solver.solve(qp)
                except RuntimeError as error:
                    failures.append(str(error))
                    continue
                times.append(time.perf_counter() - start)
                errors.append(solution_error(x, x_ref))
    max_error = max(errors) if errors else None
    agree = not failures and max_error is not None and max_error <= SOLUTION_TOLERANCE
    values = np.asarray(times) * 1e6
    return {
        "settings": solver.settings,
        "solve_us": {
            "median": float(np.median(values)) if len(values) else None,
            "p99": float(np.percentile(values, 99)) if len(values) else None,
        },
        "solves": len(times),
        "max_error": max_error,
        "agree": agree,
        "failures": len(failures),
        "stalled": solver.stalled,
        "first_failure": failures[0] if failures else None,
    }


def bench_env(key: str, config: QPBenchConfig) -> dict[str, Any]:
    """One env: record, reference, every solver (see the module docstring)."""
    recording = record_qps(ENVS[key], config.seconds, config.seed)
    if not recording.qps:
        raise RuntimeError(f"no QP recorded on {ENVS[key]}")
    references, residuals, active = [], [], 0
    for qp in recording.qps:
        x, kkt = reference_solution(qp)
        references.append(x)
        residuals.append(max(kkt.values()))
        slack = np.minimum(qp.C @ x - qp.lower, qp.upper - qp.C @ x)
        active += bool(np.any(slack <= ACTIVE_TOLERANCE * (1.0 + np.abs(qp.upper).max())))
    first = recording.qps[0]
    solvers = {
        solver.name: _run_solver(
            solver, recording, references, config.passes, f"{key} QP {solver.name}"
        )
        for solver in all_solvers()
    }
    return {
        "env": ENVS[key],
        "controller": "unified",
        "seconds": config.seconds,
        "qps": len(recording.qps),
        "variables": first.n,
        "constraints": first.m,
        "qps_with_active_constraints": active,
        "controller_qp_failures": recording.controller_failures,
        "reference": "quadprog, KKT-checked",
        "reference_kkt_max": max(residuals),
        "solution_tolerance": SOLUTION_TOLERANCE,
        "passes": config.passes,
        "solvers": solvers,
    }


def run(config: QPBenchConfig) -> dict[str, Any]:
    return {key: bench_env(key, config) for key in ENVS}


__all__ = ["ENVS", "QPBenchConfig", "bench_env", "run"]
