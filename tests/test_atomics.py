"""The atomics of the vector env's threads (wip_gym/vector/atomics.py): each operation's
result, and two threads that increment one counter a million times each, with adds and with
compare-and-swap loops, losing no increment."""

from __future__ import annotations

import threading

import numpy as np
from numba import njit

from wip_gym.vector.atomics import atomic_add, atomic_load, atomic_store, atomic_swap


@njit(nogil=True)
def _each_once(a: np.ndarray) -> tuple[int, int, bool, bool, int]:
    atomic_store(a, 1, 5)
    before = atomic_add(a, 1, 2)
    swapped = atomic_swap(a, 1, 7, 9)
    refused = atomic_swap(a, 1, 7, 11)
    return before, atomic_load(a, 1), swapped, refused, atomic_load(a, 0)


@njit(nogil=True)
def _count(a: np.ndarray, n: int) -> None:
    for _ in range(n):
        atomic_add(a, 0, 1)
        while True:  # the same by compare-and-swap, as the vector env claims sub-envs
            word = atomic_load(a, 1)
            if atomic_swap(a, 1, word, word + 1):
                break


def test_each_operation_does_what_it_says() -> None:
    a = np.array([3, 0, 0], dtype=np.int64)
    assert _each_once(a) == (5, 9, True, False, 3)
    np.testing.assert_array_equal(a, [3, 9, 0])


def test_two_threads_lose_no_increment() -> None:
    a = np.zeros(2, dtype=np.int64)
    n = 1_000_000
    threads = [threading.Thread(target=_count, args=(a, n)) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    np.testing.assert_array_equal(a, [2 * n, 2 * n])
