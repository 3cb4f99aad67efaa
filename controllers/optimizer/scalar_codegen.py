"""Straight-line scalar code from a jaxpr, compiled by numba: JAX's autodiff writes the
derivatives, numba runs them without XLA's per-call and per-loop costs.

``scalar_source(fun, *example_args)`` traces ``fun`` to a jaxpr (``jax.make_jaxpr``) and
writes it out element by element: every array of the jaxpr (small, fixed shapes) becomes one
Python variable per entry, every element-wise primitive one statement per entry, and the
structural primitives (slices, reshapes, concatenations, broadcasts, transposes) only rename
entries. ``jit`` and ``custom_jvp_call`` are inlined; ``cond`` becomes ``if``/``else``. The
result reads its inputs from one flat float vector and writes its outputs into another. It
covers the primitives the WIPM's problems use and refuses any other by name
(:data:`ELEMENTWISE`, :data:`REDUCTIONS`, :data:`STRUCTURAL`). NumPy's error model is kept (a
division by zero gives inf or NaN, as in JAX) and so are JAX's NaN semantics of ``max`` and
``min``.

The MPC's compiled backend (``controllers.optimizer.numba_ddp``) writes its per-step functions
with it. Tested against JAX on random inputs and corner cases (tests/test_scalar_codegen.py).
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Callable, Sequence
from typing import Any

import numba
import numpy as np

#: element-wise primitives: name -> a format of the operands' entries
ELEMENTWISE: dict[str, Callable[..., str]] = {
    "add": lambda a, b: f"{a} + {b}",
    "add_any": lambda a, b: f"{a} + {b}",
    "sub": lambda a, b: f"{a} - {b}",
    "mul": lambda a, b: f"{a} * {b}",
    "div": lambda a, b: f"{a} / {b}",
    "neg": lambda a: f"-{a}",
    "max": lambda a, b: f"nan_max({a}, {b})",
    "min": lambda a, b: f"nan_min({a}, {b})",
    "sin": lambda a: f"math.sin({a})",
    "cos": lambda a: f"math.cos({a})",
    "sqrt": lambda a: f"math.sqrt({a})",
    "exp": lambda a: f"math.exp({a})",
    "log": lambda a: f"math.log({a})",
    "tanh": lambda a: f"math.tanh({a})",
    "abs": lambda a: f"abs({a})",
    "gt": lambda a, b: f"{a} > {b}",
    "ge": lambda a, b: f"{a} >= {b}",
    "lt": lambda a, b: f"{a} < {b}",
    "le": lambda a, b: f"{a} <= {b}",
    "eq": lambda a, b: f"{a} == {b}",
    "ne": lambda a, b: f"{a} != {b}",
    "or": lambda a, b: f"{a} or {b}",
    "and": lambda a, b: f"{a} and {b}",
    "not": lambda a: f"not {a}",
    "is_finite": lambda a: f"math.isfinite({a})",
    "select_n": lambda p, *cases: _select(p, cases),
}
#: reductions over axes (``reduce_sum`` as a sum of the entries, in order)
REDUCTIONS = {
    "reduce_sum": "",
    "reduce_max": "max",
    "reduce_min": "min",
    "reduce_and": "all",
    "reduce_or": "any",
}
#: primitives that only move entries (handled in ``_Writer._structural``)
STRUCTURAL = (
    "slice",
    "squeeze",
    "reshape",
    "transpose",
    "concatenate",
    "broadcast_in_dim",
    "stack",
    "unstack",
    "pad",
    "split",
    "copy",
    "copy_p",
)


@numba.njit(cache=True)
def nan_max(a: float, b: float) -> float:
    """``jnp.maximum``'s NaN semantics (Python's ``max`` drops a NaN second argument)."""
    return a if (a > b or a != a) else b


@numba.njit(cache=True)
def nan_min(a: float, b: float) -> float:
    """``jnp.minimum``'s NaN semantics."""
    return a if (a < b or a != a) else b


def _select(predicate: str, cases: Sequence[str]) -> str:
    if len(cases) != 2:
        raise NotImplementedError("select_n with more than two cases")
    return f"({cases[1]} if {predicate} else {cases[0]})"


def _literal(value: Any) -> str:
    value = np.asarray(value)
    if value.dtype == np.bool_:
        return "True" if bool(value) else "False"
    if np.issubdtype(value.dtype, np.integer):
        return str(int(value)) if int(value) >= 0 else f"({int(value)})"
    v = float(value)
    if math.isnan(v):
        return "math.nan"
    if math.isinf(v):
        return "math.inf" if v > 0 else "(-math.inf)"
    # a negative literal in parentheses: "-1.0 ** 2" would read as -(1.0 ** 2)
    return repr(v) if v >= 0 or math.copysign(1.0, v) > 0 else f"({v!r})"


_VARIABLE = re.compile(r"^t\d+$")


def _is_literal(entry: str) -> bool:
    """Whether a generated entry is a literal (``_literal``'s output), not a variable."""
    return _VARIABLE.match(entry) is None


def _value(entry: str) -> Any:
    """A literal entry's value."""
    return eval(entry, {"math": math})  # noqa: S307


class _Writer:
    """Writes a jaxpr's equations as scalar statements; arrays are object arrays of names."""

    def __init__(self, fold: bool = False) -> None:
        self.lines: list[str] = []
        self.names = itertools.count()
        self.fold = fold

    def fresh(self) -> str:
        return f"t{next(self.names)}"

    def emit(self, indent: str, name: str, expression: str) -> None:
        self.lines.append(f"{indent}{name} = {expression}")

    def run(self, jaxpr: Any, consts: Sequence[Any], args: Sequence[np.ndarray], indent: str):  # noqa: ANN201
        """The jaxpr's outputs (object arrays of names or literals) for ``args``."""
        env: dict[Any, np.ndarray] = {}

        def read(v: Any) -> np.ndarray:
            if hasattr(v, "val"):  # a Literal
                return np.full(np.shape(v.val), _literal(v.val), dtype=object)
            return env[v]

        for var, const in zip(jaxpr.constvars, consts, strict=True):
            arr = np.asarray(const)
            env[var] = np.array([_literal(c) for c in arr.ravel()], dtype=object).reshape(arr.shape)
        for var, arg in zip(jaxpr.invars, args, strict=True):
            env[var] = arg
        for eqn in jaxpr.eqns:
            ins = [read(v) for v in eqn.invars]
            outs = self.equation(eqn, ins, indent)
            for var, out in zip(eqn.outvars, outs, strict=True):
                entries = np.empty((), dtype=object) if np.ndim(out) == 0 else out
                if np.ndim(out) == 0:
                    entries[()] = out[()] if isinstance(out, np.ndarray) else out
                env[var] = entries
        return [read(v) for v in jaxpr.outvars]

    def equation(self, eqn: Any, ins: list[np.ndarray], indent: str) -> list[np.ndarray]:
        name, params = eqn.primitive.name, eqn.params
        if name in ELEMENTWISE:
            dtypes = {np.dtype(v.aval.dtype) for v in eqn.invars}
            if name in ("and", "or", "not") and dtypes != {np.dtype(bool)}:
                raise NotImplementedError(f"{name} of non-boolean operands (bitwise in JAX)")
            if name == "div" and not np.issubdtype(
                np.dtype(eqn.outvars[0].aval.dtype), np.floating
            ):
                raise NotImplementedError("integer division")
            shape = eqn.outvars[0].aval.shape
            operands = [np.broadcast_to(a, shape) for a in ins]
            out = np.empty(shape, dtype=object)
            for index in np.ndindex(*shape):
                entries = [a[index] for a in operands]
                folded = self._fold(name, entries) if self.fold else None
                if folded is not None:
                    out[index] = folded
                    continue
                target = self.fresh()
                self.emit(indent, target, ELEMENTWISE[name](*entries))
                out[index] = target
            return [out]
        if name == "integer_pow":
            return [self._map(ins[0], lambda a: f"({a}) ** {params['y']}", indent)]
        if name == "convert_element_type":
            dtype = np.dtype(params["new_dtype"])
            source = np.dtype(eqn.invars[0].aval.dtype)
            if dtype == np.bool_:
                form = "bool({})"
            elif source == np.bool_:  # numba has no float(bool) or int(bool)
                form = (
                    "(1 if {} else 0)"
                    if np.issubdtype(dtype, np.integer)
                    else "(1.0 if {} else 0.0)"
                )
            elif np.issubdtype(dtype, np.integer):
                form = "int({})"
            else:
                form = "float({})"
            return [self._map(ins[0], form.format, indent)]
        if name in ("jit", "pjit"):
            closed = params["jaxpr"]
            return self.run(closed.jaxpr, closed.consts, ins, indent)
        if name == "custom_jvp_call":
            closed = params["call_jaxpr"]
            return self.run(closed.jaxpr, closed.consts, ins, indent)
        if name == "cond":
            return self._cond(eqn, ins, indent)
        if name in STRUCTURAL:
            return self._structural(name, params, ins, eqn)
        if name == "iota":
            shape, dimension = tuple(params["shape"]), params["dimension"]
            values = np.indices(shape)[dimension] if shape else np.zeros(())
            cast = int if np.issubdtype(np.dtype(params["dtype"]), np.integer) else float
            literal = np.vectorize(lambda v: _literal(cast(v)), otypes=[object])
            return [literal(values)]
        if name in REDUCTIONS:
            return [self._reduce(name, ins[0], tuple(params["axes"]), indent)]
        if name == "dot_general":
            return [self._dot(ins[0], ins[1], params["dimension_numbers"], indent)]
        raise NotImplementedError(f"no scalar form for the primitive {name!r}")

    def _sum_of(self, terms: list[str], indent: str) -> str:
        target = self.fresh()
        self.emit(indent, target, " + ".join(terms) if terms else "0.0")
        return target

    def _reduce(self, name: str, a: np.ndarray, axes: tuple[int, ...], indent: str) -> np.ndarray:
        kept = [d for d in range(a.ndim) if d not in axes]
        moved = a.transpose(kept + list(axes))
        shape = moved.shape[: len(kept)]
        out = np.empty(shape, dtype=object)
        if any(a.shape[d] == 0 for d in axes):
            raise NotImplementedError(f"{name} over an empty axis")
        for index in np.ndindex(*shape):
            entries = list(moved[index].ravel())
            if name == "reduce_sum":
                out[index] = self._sum_of(entries, indent)
            elif name in ("reduce_and", "reduce_or"):
                joiner = " and " if name == "reduce_and" else " or "
                target = self.fresh()
                self.emit(indent, target, f"({joiner.join(entries)})")
                out[index] = target
            else:
                target = self.fresh()
                self.emit(indent, target, f"{REDUCTIONS[name]}({', '.join(entries)})")
                out[index] = target
        return out

    def _dot(self, a: np.ndarray, b: np.ndarray, numbers: Any, indent: str) -> np.ndarray:
        (a_contract, b_contract), (a_batch, b_batch) = numbers
        a_free = [d for d in range(a.ndim) if d not in a_contract and d not in a_batch]
        b_free = [d for d in range(b.ndim) if d not in b_contract and d not in b_batch]
        a_t = a.transpose(list(a_batch) + a_free + list(a_contract))
        b_t = b.transpose(list(b_batch) + b_free + list(b_contract))
        nb, na, nbf = len(a_batch), len(a_free), len(b_free)
        shape = a_t.shape[: nb + na] + b_t.shape[nb : nb + nbf]
        out = np.empty(shape, dtype=object)
        for index in np.ndindex(*shape):
            batch, i, j = index[:nb], index[nb : nb + na], index[nb + na :]
            left = a_t[batch + i].ravel()
            right = b_t[batch + j].ravel()
            terms = [f"{x} * {y}" for x, y in zip(left, right, strict=True)]
            out[index] = self._sum_of(terms, indent)
        return out

    def _fold(self, name: str, entries: list[str]) -> str | None:
        """The entry's value at generation time, or an operand it equals, if the literals
        among ``entries`` decide it (``fold``: for finite values, ``0 * x = 0``); else None."""
        if all(_is_literal(e) for e in entries):
            helpers = {"math": math, "nan_max": nan_max.py_func, "nan_min": nan_min.py_func}
            return _literal(eval(ELEMENTWISE[name](*entries), helpers))  # noqa: S307
        zero = [_is_literal(e) and float(_value(e)) == 0.0 for e in entries]
        one = [_is_literal(e) and float(_value(e)) == 1.0 for e in entries]
        if name == "mul" and any(zero):
            return "0.0"
        if name == "mul" and one[0]:
            return entries[1]
        if name == "mul" and one[1]:
            return entries[0]
        if name in ("add", "add_any") and zero[0]:
            return entries[1]
        if name in ("add", "add_any", "sub") and zero[1]:
            return entries[0]
        if name == "select_n" and _is_literal(entries[0]):
            return entries[2] if _value(entries[0]) else entries[1]
        return None

    def _map(self, a: np.ndarray, form: Callable[[str], str], indent: str) -> np.ndarray:
        out = np.empty(a.shape, dtype=object)
        for index in np.ndindex(*a.shape):
            target = self.fresh()
            self.emit(indent, target, form(a[index]))
            out[index] = target
        return out

    def _cond(self, eqn: Any, ins: list[np.ndarray], indent: str) -> list[np.ndarray]:
        branches = eqn.params["branches"]
        index, operands = ins[0], ins[1:]
        outs = [np.empty(v.aval.shape, dtype=object) for v in eqn.outvars]
        for out in outs:
            for i in np.ndindex(*out.shape):
                out[i] = self.fresh()
        for k, branch in enumerate(branches):
            head = "if" if k == 0 else ("elif" if k < len(branches) - 1 else "else")
            self.lines.append(
                f"{indent}{head} {index[()]} == {k}:" if head != "else" else f"{indent}else:"
            )
            results = self.run(branch.jaxpr, branch.consts, operands, indent + "    ")
            for out, result in zip(outs, results, strict=True):
                for i in np.ndindex(*out.shape):
                    self.emit(indent + "    ", out[i], result[i])
        return outs

    def _structural(
        self, name: str, params: dict[str, Any], ins: list[np.ndarray], eqn: Any
    ) -> list[np.ndarray]:
        a = ins[0]
        if name in ("copy", "copy_p"):
            return [a]
        if name == "slice":
            strides = params["strides"] or (1,) * a.ndim
            index = tuple(
                slice(s, e, st)
                for s, e, st in zip(
                    params["start_indices"], params["limit_indices"], strides, strict=True
                )
            )
            return [a[index]]
        if name == "squeeze":
            return [np.squeeze(a, axis=tuple(params["dimensions"]))]
        if name == "reshape":
            if params.get("dimensions") is not None:
                raise NotImplementedError("reshape with dimensions")
            return [a.reshape(params["new_sizes"])]
        if name == "transpose":
            return [a.transpose(params["permutation"])]
        if name == "concatenate":
            return [np.concatenate(ins, axis=params["dimension"])]
        if name == "stack":
            return [np.stack(ins, axis=params["axis"])]
        if name == "unstack":
            return [np.take(a, i, axis=params["axis"]) for i in range(a.shape[params["axis"]])]
        if name == "split":
            axis, cuts = params["axis"], np.cumsum(params["sizes"])[:-1]
            return list(np.split(a, cuts, axis=axis))
        if name == "broadcast_in_dim":
            shape = params["shape"]
            expanded = [1] * len(shape)
            for source, target in enumerate(params["broadcast_dimensions"]):
                expanded[target] = a.shape[source]
            return [np.broadcast_to(a.reshape(expanded), shape).copy()]
        if name == "pad":
            value = ins[1][()]
            config = params["padding_config"]
            if any(interior != 0 for _, _, interior in config):
                raise NotImplementedError("pad with interior padding")
            if any(lo < 0 or hi < 0 for lo, hi, _ in config):
                raise NotImplementedError("pad with negative padding")
            out = np.full(eqn.outvars[0].aval.shape, value, dtype=object)
            out[tuple(slice(lo, lo + n) for (lo, _, _), n in zip(config, a.shape, strict=True))] = a
            return [out]
        raise NotImplementedError(name)


def scalar_source(
    fun: Callable[..., Any], *example_args: Any, name: str = "stage", fold: bool = False
) -> tuple[str, int, int]:
    """``(source, inputs, outputs)``: the Python source of ``name(z, out)``, which computes
    ``fun`` on the float leaves of its arguments read in order from ``z`` and writes the leaves
    of its result in order into ``out``; and the two lengths. ``fold``: fold what the literals
    decide (constants, ``0 * x``, ``x + 0``, ``1 * x``, selects on a constant): the same values
    where every intermediate value is finite (``0 * inf`` and ``0 * nan`` fold to 0, where JAX
    gives NaN)."""
    import jax  # noqa: PLC0415

    closed = jax.make_jaxpr(fun)(*example_args)
    writer = _Writer(fold)
    args: list[np.ndarray] = []
    offset = 0
    for var in closed.jaxpr.invars:
        shape = var.aval.shape
        arr = np.empty(shape, dtype=object)
        for index in np.ndindex(*shape):
            target = writer.fresh()
            writer.emit("    ", target, f"z[{offset}]")
            arr[index] = target
            offset += 1
        args.append(arr)
    outs = writer.run(closed.jaxpr, closed.consts, args, "    ")
    k = 0
    for out in outs:
        for index in np.ndindex(*out.shape):
            writer.lines.append(f"    out[{k}] = {out[index]}")
            k += 1
    source = "\n".join([f"def {name}(z, out):", *writer.lines, "    return None", ""])
    return source, offset, k


def scalar_function(
    fun: Callable[..., Any], *example_args: Any, fold: bool = False
) -> tuple[Callable[..., None], int, int]:
    """``scalar_source`` compiled by numba: ``(function(z, out), inputs, outputs)``."""
    source, inputs, outputs = scalar_source(fun, *example_args, fold=fold)
    namespace: dict[str, Any] = {"math": math, "nan_max": nan_max, "nan_min": nan_min}
    exec(compile(source, "<scalar_codegen>", "exec"), namespace)  # noqa: S102
    # numpy's error model: a division by zero gives inf or NaN, as in JAX, not an exception
    return numba.njit(cache=False, error_model="numpy")(namespace["stage"]), inputs, outputs
