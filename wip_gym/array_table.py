"""A compiled call's arrays, declared once, handed to it as one table of addresses.

numba unboxes every array argument of a call made from Python (measured: a call of 52 array
arguments spent 14 us of its 36 us in that, against 22 us for the same call made from compiled
code). A control step's arrays are buffers made once (MuJoCo's, the robot model's, the task
stack's, the QP kernel's), so their addresses can be taken once too, and a call unboxes one
array instead of fifty.

Each compiled entry point declares its arrays once, as a :class:`TableSpec` of ``(name,
kind)`` pairs. From it come

* the table (:meth:`TableSpec.table`): one int64 row per array, ``(address, kind, d0, d1,
  d2)``, built from the arrays by name, each checked against its declared kind (float64 of 1
  to 3 dimensions, int64 of 1 or 2, C-contiguous);
* the indices (:attr:`TableSpec.index`): a namedtuple of each name's row, a module-level
  constant that compiled code reads as ``float_vector(table[I.name])`` (numba folds a global
  namedtuple's fields into the machine code: no lookup at run time).

A spec may extend another (``base``): its first rows are the base's, so a compiled function
written for the base reads a table of the extension as well.

The readers (:func:`float_vector`, :func:`float_matrix`, :func:`float_cube`, :func:`int_vector`,
:func:`int_matrix`) view a row as the array it holds, and raise when the row is of another
kind. A table is valid while its arrays are the ones it was built from: it keeps a reference to
each (so none is freed), and whoever builds it builds it again when one is replaced by a new
array instead of written in place.
"""

from __future__ import annotations

from collections import namedtuple
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numba import carray, njit, types
from numba.extending import intrinsic
from numpy.typing import NDArray

FLOAT_VECTOR, FLOAT_MATRIX, FLOAT_CUBE, INT_VECTOR, INT_MATRIX = 1, 2, 3, 11, 12
"""Row kinds: float64 of 1 to 3 dimensions, int64 of 1 or 2."""

_KINDS: dict[tuple[np.dtype[np.generic], int], int] = {
    (np.dtype(np.float64), 1): FLOAT_VECTOR,
    (np.dtype(np.float64), 2): FLOAT_MATRIX,
    (np.dtype(np.float64), 3): FLOAT_CUBE,
    (np.dtype(np.int64), 1): INT_VECTOR,
    (np.dtype(np.int64), 2): INT_MATRIX,
}
_KIND_NAMES = {kind: f"{dtype} of {ndim} dimensions" for (dtype, ndim), kind in _KINDS.items()}


class ArrayTable:
    """The table of ``arrays`` (module docstring): ``rows[i] = (address, kind, d0, d1, d2)``,
    ``names`` the arrays' names.

    Raises ``ValueError`` for an array compiled code could not view as it is: not a NumPy array,
    neither float64 (1 to 3 dimensions) nor int64 (1 or 2), or not C-contiguous.
    """

    def __init__(self, arrays: Sequence[NDArray[np.generic]], names: Sequence[str]) -> None:
        if len(names) != len(arrays):
            raise ValueError(f"{len(arrays)} arrays but {len(names)} names")
        rows = np.zeros((len(arrays), 5), dtype=np.int64)
        for i, (array, name) in enumerate(zip(arrays, names, strict=True)):
            rows[i] = _row(array, name)
        self.arrays = tuple(arrays)  # kept alive while the table is
        self.names = tuple(names)
        self.rows = rows

    def __reduce__(self) -> tuple[object, ...]:
        raise TypeError(
            "an array table holds addresses, which a copy or an unpickling would keep pointing "
            "at the original arrays: build a new table from the copied arrays instead"
        )


def _row(array: Any, name: str) -> tuple[int, ...]:
    if not isinstance(array, np.ndarray):
        raise ValueError(f"array table entry {name!r} is a {type(array).__name__}")
    kind = _KINDS.get((array.dtype, array.ndim))
    if kind is None:
        raise ValueError(
            f"array table entry {name!r} is {array.dtype} of {array.ndim} dimensions: "
            "a table holds float64 of 1 to 3 dimensions or int64 of 1 or 2"
        )
    if not array.flags.c_contiguous:
        raise ValueError(f"array table entry {name!r} is not C-contiguous")
    return (array.ctypes.data, kind, *array.shape, *(0,) * (3 - array.ndim))


class TableSpec:
    """The declaration of one compiled call's arrays: ``fields`` as ``(name, kind)`` pairs,
    after the fields of ``base`` if given (module docstring).

    Attributes:
        name: the call's name (in error messages and the index type's name).
        names, kinds: every field's name and kind, in row order (``base``'s first).
        index: a namedtuple of each field's row, for compiled code.
    """

    def __init__(
        self, name: str, fields: Sequence[tuple[str, int]], base: TableSpec | None = None
    ) -> None:
        inherited: list[tuple[str, int]] = (
            list(zip(base.names, base.kinds, strict=True)) if base is not None else []
        )
        pairs = [*inherited, *fields]
        names = [field for field, _ in pairs]
        twice = sorted({field for field in names if names.count(field) > 1})
        if twice:
            raise ValueError(f"table {name!r}: fields {twice} declared twice")
        unknown = [field for field, kind in pairs if kind not in _KIND_NAMES]
        if unknown:
            raise ValueError(f"table {name!r}: fields {unknown} of no known kind")
        self.name = name
        self.names: tuple[str, ...] = tuple(names)
        self.kinds: tuple[int, ...] = tuple(kind for _, kind in pairs)
        index_type = namedtuple(f"{name.title().replace('_', '')}Index", names)  # type: ignore[misc]
        self.index: Any = index_type(*range(len(names)))

    def table(self, arrays: Mapping[str, NDArray[np.generic]]) -> ArrayTable:
        """The table of ``arrays`` by name: every field once, each of its declared kind
        (``ValueError`` naming what is missing, unknown or of another kind)."""
        missing = [name for name in self.names if name not in arrays]
        unknown = sorted(set(arrays) - set(self.names))
        if missing or unknown:
            raise ValueError(f"table {self.name!r}: missing {missing}, unknown {unknown}")
        ordered = [arrays[name] for name in self.names]
        table = ArrayTable(ordered, self.names)
        for name, kind, row in zip(self.names, self.kinds, table.rows, strict=True):
            if row[1] != kind:
                raise ValueError(
                    f"table {self.name!r}: {name!r} is {_KIND_NAMES[int(row[1])]}, declared "
                    f"{_KIND_NAMES[kind]}"
                )
        return table


def field_offsets(name: str, fields: Sequence[tuple[str, int]]) -> tuple[Any, int]:
    """A vector's layout declared once: ``fields`` as ``(name, length)`` pairs in order give a
    namedtuple of each field's first index (a module-level constant compiled code folds, as
    :attr:`TableSpec.index`) and the vector's length."""
    names = [field for field, _ in fields]
    offsets = np.cumsum([0, *(length for _, length in fields)])
    index_type = namedtuple(f"{name.title().replace('_', '')}Offsets", names)  # type: ignore[misc]
    return index_type(*(int(offset) for offset in offsets[:-1])), int(offsets[-1])


def _pointer_intrinsic(element: types.Type) -> Any:
    """An intrinsic ``(element *) address`` for compiled code, for ``numba.carray``: a view of a
    buffer whose address was taken once."""

    def pointer(typingctx: Any, address: Any) -> Any:
        if not isinstance(address, types.Integer):
            return None
        signature = types.CPointer(element)(address)

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            return builder.inttoptr(args[0], context.get_value_type(sig.return_type))

        return signature, codegen

    pointer.__name__ = f"{element}_pointer"
    return intrinsic(pointer)


float64_pointer: Any = _pointer_intrinsic(types.float64)
"""``(double *) address`` in compiled code."""
int64_pointer: Any = _pointer_intrinsic(types.int64)
"""``(int64_t *) address`` in compiled code."""
int32_pointer: Any = _pointer_intrinsic(types.int32)
"""``(int *) address`` in compiled code (the contacts' geom ids: ``wip_gym.envs.measures``)."""


@njit(cache=True)
def float64_view(address: int, shape: tuple[int, ...]) -> np.ndarray:
    """In compiled code, the C-contiguous float64 array of ``shape`` at ``address``: a view,
    read and written in place."""
    return carray(float64_pointer(np.uint64(address)), shape)


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
    return carray(float64_pointer(np.uint64(row[0])), (row[2],))


@njit(cache=True)
def float_matrix(row: NDArray[np.int64]) -> NDArray[np.float64]:
    """The float64 matrix a table's ``row`` holds (a view)."""
    _check(row, FLOAT_MATRIX)
    return carray(float64_pointer(np.uint64(row[0])), (row[2], row[3]))


@njit(cache=True)
def float_cube(row: NDArray[np.int64]) -> NDArray[np.float64]:
    """The float64 array of three dimensions a table's ``row`` holds (a view)."""
    _check(row, FLOAT_CUBE)
    return carray(float64_pointer(np.uint64(row[0])), (row[2], row[3], row[4]))


@njit(cache=True)
def int_vector(row: NDArray[np.int64]) -> NDArray[np.int64]:
    """The int64 vector a table's ``row`` holds (a view)."""
    _check(row, INT_VECTOR)
    return carray(int64_pointer(np.uint64(row[0])), (row[2],))


@njit(cache=True)
def int_matrix(row: NDArray[np.int64]) -> NDArray[np.int64]:
    """The int64 matrix a table's ``row`` holds (a view)."""
    _check(row, INT_MATRIX)
    return carray(int64_pointer(np.uint64(row[0])), (row[2], row[3]))
