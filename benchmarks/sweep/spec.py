"""The sweep spec: a TOML file, validated entirely before anything runs.

Grammar (every table optional except the top-level keys marked required)::

    env = "wip_gym/PlanarTray-v0"        # required: an env id (wip_gym/NAME or NAME)
    controllers = ["unified", "decoupled-mpc"]   # required: registry names, each once
    duration = 1.5                       # required: simulated seconds per episode (> 0)
    seeds = 2                            # required: replicates per cell (>= 1)
    seed = 7                             # the sweep's seed (>= 0; default 0)
    preset = "paper"                     # a preset of the episode runner (default none);
                                         # several compose: "paper,realistic" or a list
    timeout = 600                        # wall-clock limit per episode, s (default below)
    [set]                                # base overrides, any --set key: KEY = VALUE
    "env.mass_randomization" = 0.05
    [grid]                               # the cells: every combination; KEY = [VALUES]
    "env.cup_friction" = [0.2, 0.4]
    [random]                             # drawn per episode from its seed
    "env.push_force" = { uniform = [-60.0, 60.0] }   # also loguniform = [lo, hi], choice = [..]
    [report]
    axes = ["env.cup_friction"]          # one or two grid axes for the plots (default: the
                                         # grid's axes if it has one or two; else no plots)
    [[frontier]]                         # any number of them (benchmarks/sweep/frontier.py)
    axis = "env.cup_friction"            # a grid axis with scalar values
    toward = "low"                       # where the task gets harder along the listed values:
                                         # "low" = toward the first listed, "high" = the last
    rate = 0.9                           # the carried rate that counts as holding, in [0, 1]

A key appears in at most one of ``[set]``, ``[grid]`` and ``[random]``. Values are JSON values
(finite numbers, strings, booleans, arrays). A frontier's axis is ordered as its values are
listed; where it holds numbers they must increase along the list (so that "low" is both the
first listed and the smallest number). Every problem raises :class:`SpecError` (a
``ValueError``: the CLI exits with status 2) naming the key.
"""

from __future__ import annotations

import itertools
import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym

from benchmarks import presets
from benchmarks.scenario import resolve_env_id
from benchmarks.sweep import keys as sweep_keys
from benchmarks.sweep.seeding import cell_seed, episode_id, key_stream
from controllers.registry import controller_names
from wip_gym.envs.base import wip_env

TOP_LEVEL = ("env", "controllers", "duration", "seeds", "seed", "preset", "timeout")
TABLES = ("set", "grid", "random", "report", "frontier")
DISTRIBUTIONS = ("uniform", "loguniform", "choice")
FRONTIER_KEYS = ("axis", "toward", "rate")
TOWARD = ("low", "high")
# Per-episode wall-clock limit unless the spec sets one: generous against a cold JAX compile
# cache (tens of seconds per new problem) and a real-time factor well under 1.
DEFAULT_TIMEOUT_BASE_S = 300.0
DEFAULT_TIMEOUT_PER_SIM_S = 20.0


class SpecError(ValueError):
    """A sweep spec that cannot run; the message names the offending key."""


@dataclass(frozen=True)
class Distribution:
    """A ``[random]`` key's distribution: ``uniform`` or ``loguniform`` over ``[low, high]``,
    or ``choice`` among values (each equally likely)."""

    kind: str
    values: tuple[Any, ...]

    def draw(self, rng: Any) -> Any:
        if self.kind == "uniform":
            return float(rng.uniform(self.values[0], self.values[1]))
        if self.kind == "loguniform":
            low, high = math.log(self.values[0]), math.log(self.values[1])
            return float(math.exp(rng.uniform(low, high)))
        return self.values[int(rng.integers(len(self.values)))]

    def extremes(self) -> tuple[Any, ...]:
        """The values whose validity covers every draw (bounds, or every choice)."""
        return self.values

    def as_json(self) -> dict[str, list[Any]]:
        return {self.kind: list(self.values)}


@dataclass(frozen=True)
class Frontier:
    """A ``[[frontier]]`` table: along the grid axis ``axis`` the task gets harder ``toward``
    its ``"low"`` (first listed) or ``"high"`` (last listed) values; a carried rate of at least
    ``rate`` counts as holding (docs/sweeps.md §5)."""

    axis: str
    toward: str
    rate: float

    def easiest_first(self, values: Sequence[Any]) -> list[Any]:
        """The axis' listed ``values`` from the easiest to the hardest."""
        return list(values) if self.toward == "high" else list(reversed(values))

    def as_json(self) -> dict[str, Any]:
        return {"axis": self.axis, "toward": self.toward, "rate": self.rate}


@dataclass(frozen=True)
class Episode:
    """One (cell, replicate, controller) of a sweep, everything resolved."""

    id: str
    cell_index: int
    cell: dict[str, Any]
    parameters: dict[str, Any]  # [set] + the cell's grid values + this episode's random draws
    random: dict[str, Any]  # the draws alone
    controller: str
    replicate: int
    seed: int


@dataclass(frozen=True)
class SweepSpec:
    env: str
    controllers: tuple[str, ...]
    duration: float
    seeds: int
    seed: int = 0
    preset: str | None = None
    timeout: float | None = None
    base: dict[str, Any] = field(default_factory=dict)
    grid: dict[str, tuple[Any, ...]] = field(default_factory=dict)
    random: dict[str, Distribution] = field(default_factory=dict)
    report_axes: tuple[str, ...] = ()
    frontiers: tuple[Frontier, ...] = ()
    text: str = ""

    @property
    def episode_timeout(self) -> float:
        if self.timeout is not None:
            return self.timeout
        return DEFAULT_TIMEOUT_BASE_S + DEFAULT_TIMEOUT_PER_SIM_S * self.duration

    def cells(self) -> list[dict[str, Any]]:
        """Every combination of the grid's values, the first axis slowest."""
        axes = list(self.grid)
        return [
            dict(zip(axes, values, strict=True))
            for values in itertools.product(*self.grid.values())
        ]

    def episodes(self) -> list[Episode]:
        """Every episode, replicate by replicate, cell by cell, controller by controller: the
        first replicate of every cell runs before any cell's second, so a sweep stopped early
        (or resumed later) holds a balanced map rather than finished and missing cells. An
        episode's id and seed do not depend on this order."""
        random_spec = {key: dist.as_json() for key, dist in self.random.items()}
        episodes = []
        cells = list(enumerate(self.cells()))
        for replicate in range(self.seeds):
            for index, cell in cells:
                resolved = {**self.base, **cell}
                seed = cell_seed(self.env, self.preset, resolved, replicate, self.seed)
                draws = {key: dist.draw(key_stream(seed, key)) for key, dist in self.random.items()}
                for controller in self.controllers:
                    identity = episode_id(
                        self.env,
                        self.preset,
                        self.duration,
                        resolved,
                        random_spec,
                        controller,
                        replicate,
                        self.seed,
                    )
                    episodes.append(
                        Episode(
                            id=identity,
                            cell_index=index,
                            cell=dict(cell),
                            parameters={**resolved, **draws},
                            random=draws,
                            controller=controller,
                            replicate=replicate,
                            seed=seed,
                        )
                    )
        return episodes


def _require(table: Mapping[str, Any], name: str, kind: type | tuple[type, ...]) -> Any:
    if name not in table:
        raise SpecError(f"the spec has no {name!r} (required)")
    value = table[name]
    if not isinstance(value, kind) or isinstance(value, bool):
        raise SpecError(f"bad value for {name!r}: {value!r}")
    return value


def _number(name: str, value: Any, *, positive: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise SpecError(f"bad value for {name!r}: {value!r} is not a finite number")
    if positive and value <= 0:
        raise SpecError(f"bad value for {name!r}: {value} must be positive")
    return float(value)


def _table(data: Mapping[str, Any], name: str) -> dict[str, Any]:
    table = data.get(name, {})
    if not isinstance(table, dict):
        raise SpecError(f"[{name}] must be a table, got {table!r}")
    return table


def _distribution(key: str, value: Any) -> Distribution:
    if not isinstance(value, dict) or len(value) != 1:
        raise SpecError(
            f"bad [random] value for {key!r}: {value!r}; expected one of "
            f"{{ uniform = [lo, hi] }}, {{ loguniform = [lo, hi] }}, {{ choice = [v, ...] }}"
        )
    kind, values = next(iter(value.items()))
    if kind not in DISTRIBUTIONS:
        raise SpecError(
            f"bad [random] value for {key!r}: unknown distribution {kind!r}; "
            f"valid: {list(DISTRIBUTIONS)}"
        )
    if not isinstance(values, list) or not values:
        raise SpecError(f"bad [random] value for {key!r}: {kind} needs a non-empty array")
    if kind == "choice":
        return Distribution(kind, tuple(values))
    if len(values) != 2:
        raise SpecError(f"bad range for {key!r}: {kind} takes [low, high], got {values!r}")
    low, high = (_number(key, v, positive=kind == "loguniform") for v in values)
    if not low < high:
        raise SpecError(f"bad range for {key!r}: low {low} must be below high {high}")
    return Distribution(kind, (low, high))


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _frontiers(tables: Any, grid: Mapping[str, Sequence[Any]]) -> tuple[Frontier, ...]:
    """The ``[[frontier]]`` tables, each checked against the grid."""
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise SpecError(
            f"bad frontier {tables!r}: write each as a [[frontier]] table with "
            f"{list(FRONTIER_KEYS)}"
        )
    frontiers = []
    for number, table in enumerate(tables, 1):
        name = f"[[frontier]] {number}"
        unknown = [k for k in table if k not in FRONTIER_KEYS]
        if unknown:
            raise SpecError(f"unknown {name} keys {unknown}; valid: {list(FRONTIER_KEYS)}")
        missing = [k for k in FRONTIER_KEYS if k not in table]
        if missing:
            raise SpecError(f"{name} has no {missing} (required: {list(FRONTIER_KEYS)})")
        axis, toward, rate = table["axis"], table["toward"], table["rate"]
        if axis not in grid:
            raise SpecError(f"{name} axis {axis!r} is not a [grid] key; grid: {list(grid)}")
        if toward not in TOWARD:
            raise SpecError(f"{name} toward {toward!r} must be one of {list(TOWARD)}")
        if not _is_number(rate) or not 0.0 <= rate <= 1.0:
            raise SpecError(f"{name} rate {rate!r} must be a number in [0, 1]")
        values = grid[axis]
        unordered = [v for v in values if not isinstance(v, str | int | float)]
        if unordered:
            raise SpecError(
                f"{name} axis {axis!r} cannot be ordered: {unordered} are not numbers, strings "
                f"or booleans"
            )
        numbers = [v for v in values if _is_number(v)]
        if any(a >= b for a, b in itertools.pairwise(numbers)):
            raise SpecError(
                f"{name} axis {axis!r} lists its numbers {numbers} out of increasing order: a "
                f"frontier's axis is ordered as listed, so list them from low to high"
            )
        frontier = Frontier(axis, toward, float(rate))
        if frontier in frontiers:
            raise SpecError(f"{name} repeats an earlier frontier: {frontier.as_json()}")
        frontiers.append(frontier)
    return tuple(frontiers)


def check_env_values(
    env_id: str, base: Mapping[str, Any], values: Mapping[str, Sequence[Any]]
) -> None:
    """Build the env once per distinct value of each env key (the others at their ``[set]``
    values): its constructor checks the values (ranges, shapes) before anything runs."""
    base_kwargs = {k.removeprefix("env."): v for k, v in base.items() if k.startswith("env.")}
    trials: list[tuple[str | None, dict[str, Any]]] = [(None, base_kwargs)]
    for key, options in values.items():
        if key.startswith("env."):
            for option in options:
                trials.append((key, {**base_kwargs, key.removeprefix("env."): option}))
    for key, kwargs in trials:
        try:
            env = gym.make(env_id, max_episode_steps=-1, **kwargs)
        except (ValueError, TypeError) as error:
            named = key or ", ".join(f"env.{k}" for k in kwargs) or env_id
            raise SpecError(f"bad value for {named}: {error}") from None
        env.close()


def _has_tray(env_id: str) -> bool:
    env = gym.make(env_id, max_episode_steps=-1)
    has_tray = bool(wip_env(env).scene_options.tray)
    env.close()
    return has_tray


def _check_key(key: str, env_id: str, controllers: Sequence[str], table: str) -> None:
    try:
        sweep_keys.validate_key(key, env_id, controllers)
    except ValueError as error:
        raise SpecError(f"[{table}] {error}") from None


def _check_value(key: str, value: Any, env_id: str, controllers: Sequence[str], table: str) -> None:
    try:
        sweep_keys.validate_value(key, value, env_id, controllers)
    except ValueError as error:
        raise SpecError(f"[{table}] {error}") from None


def parse_spec(text: str, validate_env: bool = True) -> SweepSpec:
    """Parse and validate a spec's text; :class:`SpecError` naming the first problem."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise SpecError(f"the spec is not valid TOML: {error}") from None
    unknown = [k for k in data if k not in TOP_LEVEL + TABLES]
    if unknown:
        raise SpecError(f"unknown spec keys {unknown}; valid: {list(TOP_LEVEL + TABLES)}")
    try:
        env_id = resolve_env_id(_require(data, "env", str))
    except ValueError as error:
        raise SpecError(f"bad value for 'env': {error}") from None
    controllers = _require(data, "controllers", list)
    if not controllers or not all(isinstance(c, str) for c in controllers):
        raise SpecError(f"bad value for 'controllers': {controllers!r} (a non-empty array)")
    invalid = [c for c in controllers if c not in controller_names()]
    if invalid:
        raise SpecError(f"unknown controllers {invalid}; valid: {controller_names()}")
    if len(set(controllers)) != len(controllers):
        raise SpecError(f"'controllers' lists a controller twice: {controllers}")
    duration = _number("duration", _require(data, "duration", (int, float)), positive=True)
    seeds = _require(data, "seeds", int)
    if seeds < 1:
        raise SpecError(f"bad value for 'seeds': {seeds} (at least 1)")
    seed = data.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise SpecError(f"bad value for 'seed': {seed!r} (an integer >= 0)")
    preset = data.get("preset")
    if preset is not None and not (
        isinstance(preset, str)
        or (isinstance(preset, list) and all(isinstance(p, str) for p in preset))
    ):
        raise SpecError(f"bad value for 'preset': {preset!r} (a name or an array of names)")
    try:
        sweep_keys.validate_preset(preset, env_id)
        preset = presets.canonical(preset)
    except ValueError as error:
        raise SpecError(f"bad value for 'preset': {error}") from None
    timeout = data.get("timeout")
    if timeout is not None:
        timeout = _number("timeout", timeout, positive=True)

    base = _table(data, "set")
    grid_table = _table(data, "grid")
    random_table = _table(data, "random")
    report = _table(data, "report")
    for key, value in base.items():
        _check_key(key, env_id, controllers, "set")
        _check_value(key, value, env_id, controllers, "set")
    grid: dict[str, tuple[Any, ...]] = {}
    for key, values in grid_table.items():
        _check_key(key, env_id, controllers, "grid")
        if not isinstance(values, list):
            raise SpecError(f"[grid] {key!r} must be an array of values, got {values!r}")
        if not values:
            raise SpecError(f"[grid] {key!r} is an empty axis")
        for value in values:
            _check_value(key, value, env_id, controllers, "grid")
        if len({repr(v) for v in values}) != len(values):
            raise SpecError(f"[grid] {key!r} lists a value twice: {values}")
        grid[key] = tuple(values)
    random: dict[str, Distribution] = {}
    for key, value in random_table.items():
        _check_key(key, env_id, controllers, "random")
        random[key] = _distribution(key, value)
        for extreme in random[key].extremes():
            _check_value(key, extreme, env_id, controllers, "random")
    for a, b, name_a, name_b in (
        (base, grid, "set", "grid"),
        (base, random, "set", "random"),
        (grid, random, "grid", "random"),
    ):
        both = sorted(set(a) & set(b))
        if both:
            raise SpecError(f"{both} in both [{name_a}] and [{name_b}]: a key takes one place")

    unknown_report = [k for k in report if k != "axes"]
    if unknown_report:
        raise SpecError(f"unknown [report] keys {unknown_report}; valid: ['axes']")
    axes = report.get("axes")
    if axes is None:
        axes = list(grid)[:2] if 1 <= len(grid) <= 2 else []
    if not isinstance(axes, list) or len(axes) > 2:
        raise SpecError(f"bad [report] axes {axes!r}: one or two grid axes")
    for axis in axes:
        if axis not in grid:
            raise SpecError(f"[report] axis {axis!r} is not a [grid] key; grid: {list(grid)}")
    if len(set(axes)) != len(axes):
        raise SpecError(f"[report] names an axis twice: {axes}")
    frontiers = _frontiers(data.get("frontier", []), grid)

    if validate_env:
        values: dict[str, Sequence[Any]] = dict(grid)
        values.update({k: d.extremes() for k, d in random.items()})
        check_env_values(env_id, base, values)
        if frontiers and not _has_tray(env_id):
            raise SpecError(f"[[frontier]] needs a carried rate, and {env_id} has no tray to carry")
    return SweepSpec(
        env=env_id,
        controllers=tuple(controllers),
        duration=duration,
        seeds=seeds,
        seed=seed,
        preset=preset,
        timeout=timeout,
        base=dict(base),
        grid=grid,
        random=random,
        report_axes=tuple(axes),
        frontiers=frontiers,
        text=text,
    )


def load_spec(path: str | Path) -> SweepSpec:
    """Read and validate a spec file."""
    try:
        text = Path(path).read_text()
    except OSError as error:
        raise SpecError(f"cannot read the spec {str(path)!r}: {error.strerror}") from None
    return parse_spec(text)
