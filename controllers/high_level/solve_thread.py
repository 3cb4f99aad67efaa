"""One thread that runs the MPC's compiled solves beside the control loop.

A solve beside the loop (``HighLevelConfig.mpc_delay_steps > 0``) runs in this thread while the
control thread goes on. Both share the GIL: the compiled solve releases it, but whatever Python
the thread runs holds it, and the control thread waits for it when it comes back from its own
compiled calls. So the thread runs the compiled call and nothing else:
the jobs and results pass through two ``queue.SimpleQueue`` (implemented in C; a ``get`` waits
without the GIL), and the solution's Python (its arrays' views, the ``MPCStep``) is made on the
control thread (``ModelPredictiveController.take``). A ``concurrent.futures`` executor ran a
``Future``'s and its own bookkeeping in the thread around every solve.

One job at a time: :meth:`SolveThread.result` takes the one :meth:`SolveThread.submit` started.
"""

from __future__ import annotations

import queue
import threading
import weakref
from collections.abc import Callable
from typing import Any

_Job = tuple[Callable[..., Any], tuple[Any, ...]] | None


def _serve(jobs: queue.SimpleQueue[_Job], results: queue.SimpleQueue[tuple[bool, Any]]) -> None:
    """The thread's loop: run each job, put ``(True, value)`` or ``(False, exception)``; end at
    ``None``."""
    while True:
        job = jobs.get()
        if job is None:
            return
        function, args = job
        outcome: tuple[bool, Any]
        try:
            outcome = (True, function(*args))
        except BaseException as error:  # handed to the control thread, raised there
            outcome = (False, error)
        # keep nothing of a job alive in the idle thread
        job = function = args = None  # type: ignore[assignment]
        results.put(outcome)
        outcome = None  # type: ignore[assignment]


class SolveThread:
    """A daemon thread running one job at a time (module docstring). It ends after its current
    job at :meth:`close` or when the object is collected; the interpreter's exit does not
    wait for a job (a daemon thread: call ``close`` to wait)."""

    def __init__(self, name: str) -> None:
        self._jobs: queue.SimpleQueue[_Job] = queue.SimpleQueue()
        self._results: queue.SimpleQueue[tuple[bool, Any]] = queue.SimpleQueue()
        self._running = False
        self._thread = threading.Thread(
            target=_serve, args=(self._jobs, self._results), name=name, daemon=True
        )
        self._thread.start()
        # the thread holds the queues, not this object: collecting it ends the thread
        self._stop = weakref.finalize(self, self._jobs.put, None)

    @property
    def running(self) -> bool:
        """Whether a job was submitted and its result not taken yet."""
        return self._running

    def submit(self, function: Callable[..., Any], *args: Any) -> None:
        """Start ``function(*args)`` in the thread. ``RuntimeError`` if the previous job's
        result was not taken, or after :meth:`close`."""
        if not self._stop.alive:
            raise RuntimeError("the solve thread is closed")
        if self._running:
            raise RuntimeError("a job is running: take its result() before submitting another")
        self._running = True
        self._jobs.put((function, args))

    def result(self) -> Any:
        """The running job's value, waiting for it; its exception raised here.
        ``RuntimeError`` if no job is running."""
        if not self._running:
            raise RuntimeError("no job is running")
        ok, value = self._results.get()
        self._running = False
        if not ok:
            raise value
        return value

    def close(self) -> None:
        """End the thread (after its current job, whose result is dropped: take it first to
        keep it) and wait for it."""
        self._stop()
        self._thread.join()
        if self._running:
            self._results.get()
            self._running = False
