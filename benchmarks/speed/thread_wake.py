"""What handing a job to the MPC's idle thread costs the control thread, by how long it idled.

    python -m benchmarks.speed.thread_wake [--jobs 300]

With the MPC beside the loop (``HighLevelConfig.mpc_delay_steps > 0``) the control thread hands
every MPC step to ``controllers.high_level.solve_thread.SolveThread`` (``submit``) and takes its
result a few control steps later (``result``). Between two MPC steps the thread waits for 10 ms.
This times, for idle gaps of 0.2, 2 and 10 ms before each job, in the control thread: the
``submit`` call, the next few Python operations after it (the thread takes the GIL to start the
job), and ``result`` (the job long done). The job is a small compiled loop that releases the
GIL, as the MPC step does. Medians and p90 in microseconds of this machine: on a virtual
machine, waking a thread whose CPU went idle costs far more than waking a busy one
(docs/performance.md §22).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from numba import njit

from controllers.high_level.solve_thread import SolveThread

GAPS_S = (0.0002, 0.002, 0.01)


@njit(nogil=True, cache=True)
def _job(values: np.ndarray) -> float:
    """About 20 us of arithmetic without the GIL (a stand-in for the MPC's compiled step)."""
    total = 0.0
    for i in range(20000):
        total += values[i % values.shape[0]] * 1.0000001
    return total


def wake_costs(gap_s: float, jobs: int = 300) -> dict[str, tuple[float, float]]:
    """``{"submit" | "after" | "result": (median, p90)}`` in us over ``jobs`` jobs, each
    submitted after the thread idled ``gap_s`` seconds."""
    if jobs < 1 or gap_s < 0:
        raise ValueError(f"jobs must be >= 1 and gap_s >= 0, got {jobs}, {gap_s}")
    values = np.ones(100)
    _job(values)  # compiled (or loaded) before timing
    thread = SolveThread("wake-benchmark")
    samples: dict[str, list[float]] = {"submit": [], "after": [], "result": []}
    try:
        for _ in range(jobs):
            time.sleep(gap_s)
            start = time.perf_counter()
            thread.submit(_job, values)
            submitted = time.perf_counter()
            sum(range(50))  # a few Python operations, as the control step goes on
            after = time.perf_counter()
            time.sleep(0.0005)  # the job is done by now
            waited = time.perf_counter()
            thread.result()
            done = time.perf_counter()
            samples["submit"].append(submitted - start)
            samples["after"].append(after - submitted)
            samples["result"].append(done - waited)
    finally:
        thread.close()
    return {
        key: (float(np.median(v) * 1e6), float(np.percentile(v, 90) * 1e6))
        for key, v in samples.items()
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--jobs", type=int, default=300)
    args = parser.parse_args(argv)
    if args.jobs < 1:
        parser.error("--jobs must be >= 1")
    print("| thread idle before the job | submit, us (median, p90) | the next Python | result |")
    print("|---|---|---|---|")
    for gap in GAPS_S:
        costs = wake_costs(gap, args.jobs)
        cells = " | ".join(f"{costs[k][0]:.1f}, {costs[k][1]:.1f}" for k in costs)
        print(f"| {gap * 1e3:g} ms | {cells} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
