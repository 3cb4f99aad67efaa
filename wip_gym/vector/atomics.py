"""Atomic operations on int64 arrays for compiled code, for the vector env's threads
(``wip_gym.vector.compiled``): sequentially consistent loads, stores, adds and a
compare-and-swap on ``array[index]``, as LLVM emits them (numba has none of its own).

Each is an intrinsic that compiled code calls as a function (``atomic_add(sync, CLAIM, 1)``);
the array must be a C-contiguous int64 array and the index in range (not checked: compiled
callers pass their own constants).
"""

from __future__ import annotations

from typing import Any

from numba import types
from numba.extending import intrinsic

_ORDER = "seq_cst"
_ALIGN = 8


def _valid(array: Any, index: Any, *values: Any) -> bool:
    """Whether the arguments' types are an int64 array, an integer index and integers."""
    integers = all(isinstance(v, types.Integer) for v in (index, *values))
    return isinstance(array, types.Array) and array.dtype == types.int64 and integers


def _element(context: Any, builder: Any, signature: Any, args: Any) -> Any:
    """The address of ``args[0][args[1]]``."""
    array = context.make_array(signature.args[0])(context, builder, args[0])
    index = context.cast(builder, args[1], signature.args[1], types.intp)
    return builder.gep(array.data, [index])


def _load_typing(typingctx: Any, array: Any, index: Any) -> Any:
    if not _valid(array, index):
        return None

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        return builder.load_atomic(_element(context, builder, signature, args), _ORDER, _ALIGN)

    return types.int64(array, index), codegen


def _store_typing(typingctx: Any, array: Any, index: Any, value: Any) -> Any:
    if not _valid(array, index, value):
        return None

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        v = context.cast(builder, args[2], signature.args[2], types.int64)
        builder.store_atomic(v, _element(context, builder, signature, args), _ORDER, _ALIGN)
        return context.get_dummy_value()

    return types.none(array, index, value), codegen


def _add_typing(typingctx: Any, array: Any, index: Any, value: Any) -> Any:
    if not _valid(array, index, value):
        return None

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        v = context.cast(builder, args[2], signature.args[2], types.int64)
        return builder.atomic_rmw("add", _element(context, builder, signature, args), v, _ORDER)

    return types.int64(array, index, value), codegen


def _swap_typing(typingctx: Any, array: Any, index: Any, expected: Any, value: Any) -> Any:
    if not _valid(array, index, expected, value):
        return None

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        old = context.cast(builder, args[2], signature.args[2], types.int64)
        new = context.cast(builder, args[3], signature.args[3], types.int64)
        pointer = _element(context, builder, signature, args)
        pair = builder.cmpxchg(pointer, old, new, _ORDER, _ORDER)
        return builder.extract_value(pair, 1)  # i1, numba's boolean

    return types.boolean(array, index, expected, value), codegen


atomic_load: Any = intrinsic(_load_typing)
"""``atomic_load(array, index)``: ``array[index]``."""
atomic_store: Any = intrinsic(_store_typing)
"""``atomic_store(array, index, value)``: ``array[index] = value``."""
atomic_add: Any = intrinsic(_add_typing)
"""``atomic_add(array, index, value)``: ``array[index] += value``; the value before."""
atomic_swap: Any = intrinsic(_swap_typing)
"""``atomic_swap(array, index, expected, value)``: ``array[index] = value`` if it holds
``expected``; whether it did."""
