"""A loop over the sub-envs spread over threads, for the vector env's passes in Python (its
resets, and its steps where the sub-envs cannot take the compiled ones, whose own team of
threads is ``wip_gym.vector.compiled.Team``; docs/vector.md §3).

A sub-env's step is Python around two calls that release the GIL (``mujoco.mj_step`` and the
env's compiled measures, ``nogil``), so threads can overlap one sub-env's physics with
another's Python: at best, a step comes down to its Python part (about half of it). The
threads are made once and wait on a lock between steps; the calling thread takes part.
Sub-envs are handed out one at a time from a shared counter, so a slow one (a reset) does not
hold the others back; which thread steps a sub-env does not matter, as each is touched by one
thread per step and the sub-envs share nothing.
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
                target=self._serve, args=(start, done), name=f"wip-vector-{k + 1}", daemon=True
            )
            self._starts.append(start)
            self._dones.append(done)
            self._threads.append(thread)
            thread.start()

    @property
    def threads(self) -> int:
        """Threads that step (the caller's included)."""
        return len(self._threads) + 1

    def _drain(self) -> None:
        count, counter, body = self._count, self._counter, self._pass_body
        while True:
            i = next(counter)  # atomic under the GIL
            if i >= count:
                return
            try:
                body(i)
            except BaseException as error:  # raised by run() in the caller
                self._errors.append((i, error))

    def _serve(self, start: threading.Lock, done: threading.Lock) -> None:
        while True:
            start.acquire()
            if self._closed:
                done.release()
                return
            self._drain()
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
            for start in self._starts:
                start.release()
            self._drain()
            for done in self._dones:
                done.acquire()
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
