"""The sweep's frontiers: along a grid axis, the hardest value at which a controller still
carries the cup (docs/sweeps.md §5).

For a ``[[frontier]]`` (``axis``, ``toward``, ``rate``), each controller and each combination
of the other grid axes' values, the *critical value* is the hardest value of ``axis`` at which
the carried rate is at least ``rate`` there and at every easier value; None when even the
easiest value falls short. A value whose cell has no carried rate (no finished episode) does
not hold. The axis is ordered as its values are listed in the grid: ``toward = "high"`` makes
the last listed the hardest, ``"low"`` the first.
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Mapping, Sequence
from typing import Any

from benchmarks.sweep.spec import Frontier, SweepSpec


def critical_value(
    values_easiest_first: Sequence[Any], rates: Sequence[float | None], threshold: float
) -> Any | None:
    """The last of ``values_easiest_first`` up to which every rate is at least ``threshold``
    (None: the first already is not, or is missing)."""
    if len(values_easiest_first) != len(rates):
        raise ValueError(f"{len(values_easiest_first)} values against {len(rates)} rates")
    critical = None
    for value, rate in zip(values_easiest_first, rates, strict=True):
        if rate is None or rate < threshold:
            break
        critical = value
    return critical


def value_label(value: Any) -> str:
    """A grid value as a JSON object key: a string as it is, anything else as JSON
    (``1.5`` -> ``"1.5"``, ``true`` -> ``"true"``)."""
    return value if isinstance(value, str) else json.dumps(value)


def cell_key(parameters: Mapping[str, Any]) -> str:
    """The key of a cell by its grid values, whatever their order."""
    return json.dumps(dict(parameters), sort_keys=True)


def frontier_rows(spec: SweepSpec, cells: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """``summary["frontier"]``: one row per frontier, combination of the other grid axes (in
    the grid's order) and controller, with the carried rate at each value of the axis (in its
    listed order) and the critical value. ``cells`` are the summary's cells."""
    by_parameters = {cell_key(c["parameters"]): c for c in cells}
    rows = []
    for frontier in spec.frontiers:
        others = [k for k in spec.grid if k != frontier.axis]
        for combination in itertools.product(*(spec.grid[k] for k in others)):
            fixed = dict(zip(others, combination, strict=True))
            for controller in spec.controllers:
                rates = [
                    by_parameters[cell_key({**fixed, frontier.axis: value})]["controllers"][
                        controller
                    ]["carried_rate"]
                    for value in spec.grid[frontier.axis]
                ]
                rows.append(_row(frontier, controller, fixed, spec.grid[frontier.axis], rates))
    return rows


def _row(
    frontier: Frontier,
    controller: str,
    fixed: dict[str, Any],
    values: Sequence[Any],
    rates: Sequence[float | None],
) -> dict[str, Any]:
    critical = critical_value(
        frontier.easiest_first(values), frontier.easiest_first(rates), frontier.rate
    )
    return {
        "controller": controller,
        **frontier.as_json(),
        "fixed": fixed,
        "critical": critical,
        "rates": {value_label(v): r for v, r in zip(values, rates, strict=True)},
    }
