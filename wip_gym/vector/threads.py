"""Threads for the vector env's passes over its sub-envs (docs/vector.md §3).

The threads are made once and wait on a lock between passes; the calling thread takes part.
Two kinds of pass: :meth:`ParallelLoop.run` hands the indices out one at a time from a shared
counter (a reset pass: a slow sub-env does not hold the others back), and
:meth:`ParallelLoop.run_each` runs one body per thread (the compiled steps' pass, whose
threads claim sub-envs in compiled code, ``wip_gym.vector.compiled``). Which thread steps a
sub-env does not matter: each is touched by one thread per pass and the sub-envs share
nothing.
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Callable


class ParallelLoop:
    """``body(i)`` for ``i`` in ``range(count)`` on ``threads`` threads (the caller's one of
    them) at each :meth:`run` (or another body for one pass, ``run(body)``); ``threads=1``
    runs in the caller alone.

    An exception of ``body`` is raised by :meth:`run` once every index has been handed out and
    the threads have stopped (the lowest index's, if several raised).
    """

    def __init__(self, body: Callable[[int], None], count: int, threads: int) -> None:
        if count < 1 or threads < 1:
            raise ValueError(f"count and threads must be >= 1, got {count}, {threads}")
        self._body = body
        self._pass_body = body  # this pass's
        self._count = count
        self._counter = itertools.count()
        self._each = False  # this pass: body(k) once on thread k (run_each)
        self._errors: list[tuple[int, BaseException]] = []
        self._closed = False
        self._starts: list[threading.Lock] = []
        self._dones: list[threading.Lock] = []
        self._threads: list[threading.Thread] = []
        for k in range(min(threads, count) - 1):
            start, done = threading.Lock(), threading.Lock()
            start.acquire()
            done.acquire()
            thread = threading.Thread(
                target=self._serve,
                args=(start, done, k + 1),
                name=f"wip-vector-{k + 1}",
                daemon=True,
            )
            self._starts.append(start)
            self._dones.append(done)
            self._threads.append(thread)
            thread.start()

    @property
    def threads(self) -> int:
        """Threads that step (the caller's included)."""
        return len(self._threads) + 1

    def _drain(self, thread: int) -> None:
        count, counter, body = self._count, self._counter, self._pass_body
        if self._each:
            try:
                body(thread)
            except BaseException as error:  # raised by run_each() in the caller
                self._errors.append((thread, error))
            return
        while True:
            i = next(counter)  # atomic under the GIL
            if i >= count:
                return
            try:
                body(i)
            except BaseException as error:  # raised by run() in the caller
                self._errors.append((i, error))

    def _serve(self, start: threading.Lock, done: threading.Lock, thread: int) -> None:
        while True:
            start.acquire()
            if self._closed:
                done.release()
                return
            self._drain(thread)
            done.release()

    def run(self, body: Callable[[int], None] | None = None) -> None:
        """One pass over every index, of ``body`` if given (else the loop's own)."""
        if self._closed:
            raise RuntimeError("the loop is closed")
        body = self._body if body is None else body
        if not self._threads:  # one thread: a plain loop
            for i in range(self._count):
                try:
                    body(i)
                except BaseException as error:
                    self._errors.append((i, error))
        else:
            self._counter = itertools.count()
            self._pass_body = body
            self._each = False
            self._pass()
        self._raise()

    def run_each(self, body: Callable[[int], None]) -> None:
        """One pass of ``body(k)`` on each thread ``k`` (0 the caller's, up to
        :attr:`threads` - 1), each at once: for shares of work fixed in advance (handed out
        one at a time, the caller could take them all before another thread wakes)."""
        if self._closed:
            raise RuntimeError("the loop is closed")
        self._pass_body = body
        self._each = True
        self._pass()
        self._raise()

    def _pass(self) -> None:
        for start in self._starts:
            start.release()
        self._drain(0)
        for done in self._dones:
            done.acquire()

    def _raise(self) -> None:
        if self._errors:
            errors, self._errors = sorted(self._errors, key=lambda e: e[0]), []
            raise errors[0][1]

    def close(self) -> None:
        """Stop the threads (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for start in self._starts:
            start.release()
        for thread in self._threads:
            thread.join()
