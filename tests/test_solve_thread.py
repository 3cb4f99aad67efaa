"""The MPC's thread beside the control loop (``controllers.high_level.solve_thread``): one job
at a time, its value or its exception handed to the control thread, and nothing left running."""

from __future__ import annotations

import gc
import threading
import time

import pytest

from controllers.high_level.solve_thread import SolveThread


def _threads(name: str) -> list[threading.Thread]:
    return [thread for thread in threading.enumerate() if thread.name == name]


def test_jobs_run_in_the_thread_one_at_a_time() -> None:
    solver = SolveThread("test-solve-a")
    names: list[str] = []

    def job(x: int) -> int:
        names.append(threading.current_thread().name)
        time.sleep(0.01)
        return 2 * x

    for x in range(3):
        solver.submit(job, x)
        assert solver.running
        with pytest.raises(RuntimeError, match="take its result"):
            solver.submit(job, 9)
        assert solver.result() == 2 * x
        assert not solver.running
    assert names == ["test-solve-a"] * 3
    with pytest.raises(RuntimeError, match="no job is running"):
        solver.result()
    solver.close()
    assert not _threads("test-solve-a")
    with pytest.raises(RuntimeError, match="closed"):
        solver.submit(job, 1)


def test_an_exception_is_raised_on_the_control_thread_and_the_thread_goes_on() -> None:
    solver = SolveThread("test-solve-b")

    def fail() -> None:
        raise FloatingPointError("diverged")

    solver.submit(fail)
    with pytest.raises(FloatingPointError, match="diverged"):
        solver.result()
    solver.submit(lambda: 5)
    assert solver.result() == 5
    solver.close()


def test_close_drops_a_running_job_and_collection_ends_the_thread() -> None:
    solver = SolveThread("test-solve-c")
    solver.submit(time.sleep, 0.05)
    solver.close()
    assert not solver.running and not _threads("test-solve-c")
    collected = SolveThread("test-solve-d")
    collected.submit(lambda: 1)
    assert collected.result() == 1
    (thread,) = _threads("test-solve-d")
    del collected
    gc.collect()
    thread.join(timeout=5.0)
    assert not thread.is_alive()
