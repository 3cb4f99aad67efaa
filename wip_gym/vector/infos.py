"""Gymnasium's batching of the sub-envs' infos, in a few conversions per step (docs/vector.md
§2).

Gymnasium's rule (``VectorEnv._add_info``, applied to sub-env 0, 1, ... in turn): every key
becomes an array over the sub-envs, of the first supplier's type (a Python ``float`` gives
float64, ``bool`` bool, ``int`` int64, a NumPy scalar its dtype, an array its dtype with the
sub-env axis first, anything else an object array), assigned ``array[i] = value`` sub-env by
sub-env, zeros (or None) where a sub-env did not supply the key, with a boolean mask
``"_" + key``; a nested dict recurses.

:class:`InfoBatcher` gives the same dict. It keeps a layout: the keys and value types of a
step's info (every step of a wip env has the same). Right after its step each sub-env's values
are read in one call (:meth:`InfoBatcher.write`, ``operator.itemgetter``); :meth:`InfoBatcher.
batch` then makes the step's floats one array, its bools another, each other key one, and the
masks are rows of one block of ``True`` (fresh at every step, as Gymnasium's): a few
conversions per step instead of one assignment per key and sub-env. Sub-envs whose info has
other keys (a reset's info, a same-step autoreset's final info) are added to that by
Gymnasium's ``_add_info``, and a step that does not fit at all goes through ``_add_info``
entirely, sub-env by sub-env.
"""

from __future__ import annotations

import operator
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

#: ``VectorEnv._add_info``'s signature: (batched infos, one sub-env's info, its index)
AddInfo = Callable[[dict[str, Any], dict[str, Any], int], dict[str, Any]]
Row = tuple[Any, ...]


def _getter(keys: Sequence[str]) -> Callable[[dict[str, Any]], Row]:
    """The values of ``keys`` of a dict, as a tuple (``operator.itemgetter``)."""
    get = operator.itemgetter(*keys)
    return get if len(keys) != 1 else (lambda d: (get(d),))


@dataclass(frozen=True)
class InfoLayout:
    """The keys of an info and their value types; floats and bools are batched a block each,
    every other key (ints, NumPy scalars, arrays of one shape and dtype) on its own."""

    keys: tuple[str, ...]
    types: tuple[type, ...]
    values: Callable[[dict[str, Any]], Row]  # every value, in ``keys`` order
    floats: tuple[str, ...]  # the keys of Python floats
    bools: tuple[str, ...]  # of Python bools
    own: tuple[tuple[str, np.dtype[Any], tuple[int, ...]], ...]  # the others: key, dtype, shape
    row: Callable[[dict[str, Any]], Row]  # the floats', bools' and own's values, in that order

    @staticmethod
    def of(info: dict[str, Any]) -> InfoLayout | None:
        """The layout of ``info``; None if it has no key or a value needs Gymnasium's general
        rule (a dict, an object)."""
        keys = tuple(info)
        if not keys:
            return None
        types = tuple(type(v) for v in info.values())
        floats, bools, own = [], [], []
        for key, kind in zip(keys, types, strict=True):
            value = info[key]
            if kind is float:
                floats.append(key)
            elif kind is bool:
                bools.append(key)
            elif kind is int or issubclass(kind, np.number):
                own.append((key, np.dtype(kind), ()))
            elif kind is np.ndarray and value.dtype != object:
                own.append((key, value.dtype, value.shape))
            else:
                return None
        return InfoLayout(
            keys=keys,
            types=types,
            values=_getter(keys),
            floats=tuple(floats),
            bools=tuple(bools),
            own=tuple(own),
            row=_getter((*floats, *bools, *(key for key, _, _ in own))),
        )


class InfoBatcher:
    """Batches ``num_envs`` sub-envs' infos as Gymnasium's ``add_info`` (the vector env's
    ``_add_info``) does. Per step: :meth:`write` each sub-env's info (in the thread that
    stepped it), then :meth:`batch`."""

    def __init__(self, num_envs: int, add_info: AddInfo) -> None:
        self.num_envs = num_envs
        # weakly: the vector env's threads reach this batcher and must not keep the env alive
        self._add_info_of = weakref.WeakMethod(add_info)
        self._layout: InfoLayout | None = None
        self._mask_names: tuple[str, ...] = ()  # "_" + each key of the layout
        self._rows: list[Row | None] = [None] * num_envs
        self._count = -1  # the layout's number of keys

    def write(self, i: int, info: dict[str, Any] | None) -> None:
        """Keep sub-env ``i``'s info values if it has the layout's keys (the others go
        through ``add_info`` in :meth:`batch`); None: it gave no info this step."""
        row = None
        layout = self._layout
        if info is not None and layout is not None and len(info) == self._count:
            try:
                row = layout.row(info)
            except KeyError:
                row = None
        self._rows[i] = row

    def relayout(self, info: dict[str, Any]) -> None:
        """Take the layout of ``info`` for the next steps."""
        layout = InfoLayout.of(info)
        self._layout = layout
        self._count = -1 if layout is None else len(layout.keys)
        self._mask_names = () if layout is None else tuple("_" + key for key in layout.keys)

    def batch(
        self,
        infos: Sequence[dict[str, Any] | None],
        finals: Sequence[tuple[int, Any, dict[str, Any]]] = (),
    ) -> dict[str, Any]:
        """The vector env's info from the sub-envs' ``infos`` (None: that sub-env gave none,
        e.g. it was not reset), after :meth:`write` of each.

        ``finals``: ``(index, final observation, final info)`` of the sub-envs that ended and
        were reset in this step (same-step autoreset), added before that sub-env's info as
        Gymnasium's ``SyncVectorEnv`` does (``final_obs``, ``final_info`` and their masks).

        The sub-envs that fit the layout are batched at once, the others added to that by
        ``add_info`` in their order. That is Gymnasium's result when the first of those that
        fit has the layout's types (the first supplier's, whose type the arrays take) and the
        others agree with them where they share its keys: both are checked, otherwise every
        sub-env goes through ``add_info``. The values of the later sub-envs that fit are
        converted to the first's types as Gymnasium's assignment converts them."""
        n, rows, layout = self.num_envs, self._rows, self._layout
        if not finals and layout is not None and None not in rows and self._typed(infos[0]):
            batched = self._arrays(rows, range(n))  # type: ignore[arg-type]
            if batched is not None:  # the common step: every sub-env at once
                masks = np.ones((len(self._mask_names), n), dtype=np.bool_)  # one block
                batched.update(zip(self._mask_names, masks, strict=True))
                return batched
        ended = {index: (observation, info) for index, observation, info in finals}
        fitting = [i for i in range(n) if rows[i] is not None and i not in ended]
        others = [i for i in range(n) if rows[i] is None or i in ended]
        out: dict[str, Any] | None = None
        if (
            layout is not None
            and others
            and len(fitting) > len(others)
            and self._typed(infos[fitting[0]])
            and self._agrees(infos, others)
        ):
            out = self._arrays([rows[i] for i in fitting], fitting)  # type: ignore[misc]
            if out is not None:
                present = np.zeros(n, dtype=np.bool_)
                present[fitting] = True
                out.update({"_" + key: present.copy() for key in layout.keys})
        add_info = self._add_info_of()
        assert add_info is not None, "the vector env is gone"
        if out is None:  # every sub-env through add_info, and a layout for the next steps
            others, out = list(range(n)), {}
            self._adopt(infos)
        for i in others:
            if i in ended:
                observation, final_info = ended[i]
                out = add_info(out, {"final_obs": observation, "final_info": final_info}, i)
            info = infos[i]
            if info is not None:
                out = add_info(out, info, i)
        return out

    def _typed(self, info: dict[str, Any] | None) -> bool:
        """Whether ``info`` has the layout's value types (and its arrays' dtypes and shapes)."""
        layout = self._layout
        if info is None or layout is None:
            return False
        if tuple(map(type, layout.values(info))) != layout.types:
            return False
        for key, dtype, shape in layout.own:
            value = info[key]
            if isinstance(value, np.ndarray) and (value.dtype != dtype or value.shape != shape):
                return False
        return True

    def _arrays(self, rows: Sequence[Row], indices: Sequence[int]) -> dict[str, Any] | None:
        """The sub-envs at ``indices`` (their ``rows``, of the layout) as arrays over every
        sub-env, by key (the others' entries zero; no masks); None if an array key's values do
        not make one array of the layout's shape."""
        layout = self._layout
        assert layout is not None
        n, m = self.num_envs, len(indices)
        everyone = m == n
        out: dict[str, Any] = {}
        start = 0
        for names, kind in ((layout.floats, np.float64), (layout.bools, np.bool_)):
            if not names:
                continue
            end = start + len(names)
            # one conversion for the step (Python floats and bools to float64, bool: exact)
            block = np.array([row[start:end] for row in rows], dtype=kind).reshape(m, -1).T
            if everyone:
                block = np.ascontiguousarray(block)
            else:
                full = np.zeros((len(names), n), dtype=kind)
                full[:, indices] = block
                block = full
            out.update(zip(names, block, strict=True))
            start = end
        for j, (key, dtype, shape) in enumerate(layout.own):
            try:
                column = np.array([row[start + j] for row in rows], dtype=dtype)
            except (ValueError, TypeError):  # values that do not stack
                return None
            if column.shape[1:] != shape:
                return None
            if not everyone:
                full = np.zeros((n, *shape), dtype=dtype)
                full[list(indices)] = column
                column = full
            out[key] = column
        return out

    def _agrees(self, infos: Sequence[dict[str, Any] | None], indices: Sequence[int]) -> bool:
        """Whether the infos at ``indices`` have the layout's types where they have its keys
        (``add_info`` then writes their values into the arrays as Gymnasium's would)."""
        layout = self._layout
        assert layout is not None
        types = dict(zip(layout.keys, layout.types, strict=True))
        for i in indices:
            info = infos[i]
            if info is not None and any(
                key in types and type(value) is not types[key] for key, value in info.items()
            ):
                return False
        return True

    def _adopt(self, infos: Sequence[dict[str, Any] | None]) -> None:
        """After a step that did not fit: if every sub-env's info has the keys and types of
        sub-env 0's, take its layout for the next steps."""
        first = infos[0]
        if first is None:
            return
        keys, types = tuple(first), tuple(map(type, first.values()))
        layout = self._layout
        if layout is not None and (layout.keys, layout.types) == (keys, types):
            return
        for info in infos[1:]:
            if info is None or tuple(info) != keys or tuple(map(type, info.values())) != types:
                return
        self.relayout(first)
