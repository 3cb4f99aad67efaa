"""Many arrays handed to one compiled call as a single table of their addresses and shapes.

numba unboxes every array argument of a call made from Python: measured here, a call of the
task stack's 52 arguments spent 14 us of its 36 us in that, against 22 us for the same call
made from compiled code. A control step's arrays are buffers made
once (MuJoCo's, the task stack's, the QP kernel's), so their addresses can be taken once too:
:class:`ArrayTable` holds one int64 row per array, ``(address, kind, d0, d1, d2)``, and compiled
code views row ``i`` with the reader of its kind (:func:`float_vector`, :func:`float_matrix`,
:func:`float_cube`, :func:`int_vector`, :func:`int_matrix`, given ``table[i]``), which raises
when the row is of another kind. A call then unboxes one array instead of fifty.

The table is valid while its arrays are the ones computed with: it keeps a reference to each
(so none is freed), and whoever builds it must build it again when one is replaced by a new
array instead of written in place (``controllers.low_level.compiled_step`` does, and says
when).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import carray, njit
from numpy.typing import NDArray

from wip_gym import mujoco_c as mjc

FLOAT_VECTOR, FLOAT_MATRIX, FLOAT_CUBE, INT_VECTOR, INT_MATRIX = 1, 2, 3, 11, 12
"""Row kinds: float64 of 1 to 3 dimensions, int64 of 1 or 2."""

_KINDS: dict[tuple[np.dtype[np.generic], int], int] = {
    (np.dtype(np.float64), 1): FLOAT_VECTOR,
    (np.dtype(np.float64), 2): FLOAT_MATRIX,
    (np.dtype(np.float64), 3): FLOAT_CUBE,
    (np.dtype(np.int64), 1): INT_VECTOR,
    (np.dtype(np.int64), 2): INT_MATRIX,
}


class ArrayTable:
    """The table of ``arrays`` (module docstring): ``rows[i] = (address, kind, d0, d1, d2)``.

    Raises ``ValueError`` for an array compiled code could not view as it is: not a NumPy array,
    neither float64 (1 to 3 dimensions) nor int64 (1 or 2), or not C-contiguous.
    """

    def __init__(self, arrays: Sequence[NDArray[np.generic]], names: Sequence[str] | None = None):
        labels = list(names) if names is not None else [str(i) for i in range(len(arrays))]
        if len(labels) != len(arrays):
            raise ValueError(f"{len(arrays)} arrays but {len(labels)} names")
        rows = np.zeros((len(arrays), 5), dtype=np.int64)
        for i, (array, label) in enumerate(zip(arrays, labels, strict=True)):
            if not isinstance(array, np.ndarray):
                raise ValueError(f"array table entry {label!r} is a {type(array).__name__}")
            kind = _KINDS.get((array.dtype, array.ndim))
            if kind is None:
                raise ValueError(
                    f"array table entry {label!r} is {array.dtype} of {array.ndim} dimensions: "
                    "a table holds float64 of 1 to 3 dimensions or int64 of 1 or 2"
                )
            if not array.flags.c_contiguous:
                raise ValueError(f"array table entry {label!r} is not C-contiguous")
            rows[i, 0] = array.ctypes.data
            rows[i, 1] = kind
            rows[i, 2 : 2 + array.ndim] = array.shape
        self.arrays = tuple(arrays)  # kept alive while the table is
        self.names = tuple(labels)
        self.rows = rows

    def __reduce__(self) -> tuple[object, ...]:
        raise TypeError(
            "an array table holds addresses, which a copy or an unpickling would keep pointing "
            "at the original arrays: build a new table from the copied arrays instead"
        )


@njit(cache=True)
def _check(row: NDArray[np.int64], kind: int) -> None:
    if row[1] != kind:
        raise ValueError("array table: an entry read as another kind than it holds")


# The readers take a row (``table[i]``), not ``(table, i)``: numba compiles a function called from
# compiled code once per literal argument, and every entry's index is one (94 compilations of
# the check, half a minute on the first run, before this).


@njit(cache=True)
def float_vector(row: NDArray[np.int64]) -> NDArray[np.float64]:
    """The float64 vector a table's ``row`` holds (a view)."""
    _check(row, FLOAT_VECTOR)
    return carray(mjc.float64_pointer(np.uint64(row[0])), (row[2],))


@njit(cache=True)
def float_matrix(row: NDArray[np.int64]) -> NDArray[np.float64]:
    """The float64 matrix a table's ``row`` holds (a view)."""
    _check(row, FLOAT_MATRIX)
    return carray(mjc.float64_pointer(np.uint64(row[0])), (row[2], row[3]))


@njit(cache=True)
def float_cube(row: NDArray[np.int64]) -> NDArray[np.float64]:
    """The float64 array of three dimensions a table's ``row`` holds (a view)."""
    _check(row, FLOAT_CUBE)
    return carray(mjc.float64_pointer(np.uint64(row[0])), (row[2], row[3], row[4]))


@njit(cache=True)
def int_vector(row: NDArray[np.int64]) -> NDArray[np.int64]:
    """The int64 vector a table's ``row`` holds (a view)."""
    _check(row, INT_VECTOR)
    return carray(mjc.int64_pointer(np.uint64(row[0])), (row[2],))


@njit(cache=True)
def int_matrix(row: NDArray[np.int64]) -> NDArray[np.int64]:
    """The int64 matrix a table's ``row`` holds (a view)."""
    _check(row, INT_MATRIX)
    return carray(mjc.int64_pointer(np.uint64(row[0])), (row[2], row[3]))
