"""The closed loop's table in units, from ``wip-bench profile`` runs in alternating rounds.

    python -m benchmarks.speed.closed_loop_table [--rounds 2] [--duration 8] [--out out/perf]
    python -m benchmarks.speed.closed_loop_table --base REV [--rounds 5] ...

Each figure of the table is one ``wip-bench profile`` process (a fresh process per run, as a user
runs it; ``--json`` files kept in ``--out``) of the ``unified`` controller on one env and one
setting: the paper's timing (the MPC inside every tenth control step), the MPC beside the
loop (``--set unified.high_level.mpc_delay_steps=5``), and the paper's timing again without the
profiler's wrappers around the controller's parts (``--no-parts``). The wrappers, which the
rows "of which" need, cost the control step itself about 0.15 units (``benchmarks.speed.profile``):
the columns "no part timers" measure the control step and the closed loop as a user's loop
runs them, and have no "of which" rows ("-"). The runs go round by round, every
column once per round, so that a change of the machine's load spreads over all columns; a cell
shows its rounds' values side by side, and a second table their median [min, max]. Every
figure is in units of a bare, warm ``mj_step`` of Krang-v0 timed in the same process
(``benchmarks.speed.yardstick``), so the table compares across machines; the last column is
each row's target (docs/performance.md, "Targets").

Below the table it names the rounds run on a disturbed machine (:func:`disturbed_rounds`: the
env's physics in the loop, over the same steps replayed warm, more than 1.1 times its column's
least), whose every figure is off; rerun, or read the table without them.

``--base REV`` measures a change: the git revision ``REV`` is checked out into a temporary
worktree, and every round runs each column once at ``REV`` and once in this checkout; the table
shows, per column, the median [min, max] over the rounds before and after. The revision's runs
start in its worktree: ``python -m`` puts the working directory first on ``sys.path``, ahead
of ``PYTHONPATH``, so a run started here would import this checkout's code instead.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tqdm import tqdm

#: (column title, env id, extra ``wip-bench profile`` arguments)
COLUMNS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("KrangTray", "wip_gym/KrangTray-v0", ()),
    ("KrangTray, d = 5", "wip_gym/KrangTray-v0", ("--set", "unified.high_level.mpc_delay_steps=5")),
    ("PlanarTray", "wip_gym/PlanarTray-v0", ()),
    (
        "PlanarTray, d = 5",
        "wip_gym/PlanarTray-v0",
        ("--set", "unified.high_level.mpc_delay_steps=5"),
    ),
    ("KrangTray, no part timers", "wip_gym/KrangTray-v0", ("--no-parts",)),
    ("PlanarTray, no part timers", "wip_gym/PlanarTray-v0", ("--no-parts",)),
)

#: (row title, the figure's path in ``wip-bench profile --json``, its target in units or None)
ROWS: tuple[tuple[str, tuple[str, ...], float | None], ...] = (
    ("control, mean", ("control_time_units", "mean"), 5.0),
    ("control, p99", ("control_time_units", "p99"), 12.0),
    ("of which the robot model (mean)", ("per_step_units", "robot_model", "mean"), None),
    ("of which the task rows and QP (mean)", ("per_step_units", "qp_assembly", "mean"), None),
    ("of which the high level (mean)", ("per_step_units", "high_level", "mean"), None),
    ("env step, mean (physics included)", ("per_step_units", "env_step", "mean"), 2.5),
    ("of which its physics (mean)", ("per_step_units", "env_physics", "mean"), None),
    ("the same steps' bare mj_step, warm (mean)", ("per_step_units", "mujoco_step", "mean"), None),
    ("env's own work, median", ("per_step_units", "env_overhead", "median"), 1.0),
    ("closed loop, mean", ("per_step_units", "loop", "mean"), 8.0),
    ("real-time factor", ("real_time_factor",), None),
)


class MissingFigure(ValueError):
    """A profile without the figure's key: written before the figure existed (a ``--base``
    revision's)."""


class PartNotTimed(ValueError):
    """A controller part's figure of a profile run with ``--no-parts`` (``parts_timed`` false):
    the part was not timed, its cell is ``-``."""


#: the ``per_step_units`` keys that are the controller's parts (null with ``--no-parts``)
PART_KEYS = frozenset(
    {"robot_model", "qp_assembly", "qp_solve", "high_level", "python_overhead", "low_level"}
)


def figure(result: dict[str, Any], path: Sequence[str]) -> float:
    """The number at ``path`` of one profile's JSON; ``qp_assembly`` also counts ``qp_solve``
    (the task rows and the QP kernel are one compiled call: the split between them is not
    meaningful). Raises :class:`MissingFigure` for a key the profile lacks,
    :class:`PartNotTimed` for a controller part of a profile run without the part timers
    (``--no-parts``), ``ValueError`` for a part it has as ``null`` (a controller without it)."""
    if (
        result.get("parts_timed") is False
        and len(path) > 1
        and path[0] == "per_step_units"
        and path[1] in PART_KEYS
    ):
        raise PartNotTimed(f"{'.'.join(path)}: the profile ran with --no-parts")
    if tuple(path) == ("per_step_units", "qp_assembly", "mean"):
        parts = [result["per_step_units"][k] for k in ("qp_assembly", "qp_solve")]
        if any(part is None for part in parts):
            raise ValueError("the profile has no task QP (qp_assembly, qp_solve)")
        return float(sum(part["mean"] for part in parts))
    value: Any = result
    for key in path:
        if value is None:
            raise ValueError(f"the profile has no figure at {'.'.join(path)} (null)")
        if key not in value:
            raise MissingFigure(f"the profile has no key {'.'.join(path)}")
        value = value[key]
    if value is None:
        raise ValueError(f"the profile has no figure at {'.'.join(path)} (null)")
    return float(value)


#: a round whose physics in the loop, over the same steps replayed warm, is this many times its
#: column's least is flagged as run on a disturbed machine (:func:`disturbed_rounds`)
DISTURBED_RATIO = 1.1


def disturbed_rounds(results: dict[str, list[dict[str, Any]]], label: str = "") -> list[str]:
    """The rounds of each column (a list of profile JSONs) whose env physics in the loop, as a
    ratio to the same steps' bare ``mj_step`` replayed warm, exceeds :data:`DISTURBED_RATIO`
    times the column's least ratio: the controller's code moves that ratio little, a busy
    machine (another process, the MPC thread's core taken) moves it up, and with it every
    figure of the round. (The least, not the median: in a column of three rounds two may be
    disturbed.) One line per such column, e.g. ``"after KrangTray, d = 5: rounds 0, 1"``;
    profiles without the figures are skipped."""
    lines = []
    for title, runs in results.items():
        ratios = []
        for run in runs:
            parts = run.get("per_step_units", {})
            physics, floor = parts.get("env_physics"), parts.get("mujoco_step")
            if not physics or not floor or floor["mean"] <= 0:
                ratios = []
                break
            ratios.append(physics["mean"] / floor["mean"])
        if len(ratios) < 2:
            continue
        least = min(ratios)
        off = [str(i) for i, ratio in enumerate(ratios) if ratio > DISTURBED_RATIO * least]
        if off:
            lines.append(f"{label}{title}: rounds {', '.join(off)}")
    return lines


def _disturbed_note(lines: list[str]) -> list[str]:
    if not lines:
        return []
    return [
        f"rounds run on a disturbed machine (the env's physics in the loop over the same steps "
        f"warm over {DISTURBED_RATIO:g} times its column's least): {'; '.join(lines)}"
    ]


def table(results: dict[str, list[dict[str, Any]]], summary: bool = False) -> str:
    """The markdown table: a row per :data:`ROWS` entry, a column per key of ``results`` (each
    a list of profile JSONs, one per round), and the targets. A cell lists its rounds' figures,
    or with ``summary`` their median [min, max] (:func:`spread`)."""
    titles = list(results)
    lines = [
        "| per 1 ms step, units | " + " | ".join(titles) + " | target |",
        "|---" * (len(titles) + 2) + "|",
    ]
    for title, path, target in ROWS:
        values = [_timed_figures(results[t], path) for t in titles]
        if summary:
            cells = [spread(v) for v in values]
        else:
            cells = [", ".join(f"{x:.1f}" for x in v) or "-" for v in values]
        lines.append(
            f"| {title} | " + " | ".join(cells) + f" | {'' if target is None else f'{target:g}'} |"
        )
    units = [f"{r['reference_step_us']:.1f}" for t in titles for r in results[t]]
    lines.append("")
    lines.append(f"unit (bare mj_step of Krang-v0, us) per run: {', '.join(units)}")
    lines += _disturbed_note(disturbed_rounds(results))
    return "\n".join(lines)


REPO = Path(__file__).resolve().parents[2]


def profile_command(env: str, extra: Sequence[str], duration: float, path: Path) -> list[str]:
    """The ``wip-bench profile`` process of one cell (its JSON written to ``path``)."""
    return [
        sys.executable,
        "-m",
        "benchmarks.cli",
        "profile",
        "--env",
        env,
        "--controller",
        "unified",
        "--duration",
        str(duration),
        "--json",
        str(path),
        *extra,
    ]


def _profile(
    env: str, extra: Sequence[str], duration: float, path: Path, tree: Path = REPO
) -> dict[str, Any]:
    """One cell, run with ``tree``'s code (started in ``tree``, ``tree`` on ``PYTHONPATH``)."""
    environment = {**os.environ, "PYTHONPATH": str(tree)}
    subprocess.run(
        profile_command(env, extra, duration, path.resolve()),
        check=True,
        stdout=subprocess.DEVNULL,
        cwd=tree,
        env=environment,
    )
    return dict(json.loads(path.read_text()))


def _timed_figures(runs: Sequence[dict[str, Any]], path: Sequence[str]) -> list[float]:
    """The figure at ``path`` of each run; none for a part the runs did not time
    (:class:`PartNotTimed`, a column run with ``--no-parts``)."""
    try:
        return [figure(r, path) for r in runs]
    except PartNotTimed:
        return []


def _base_figures(runs: Sequence[dict[str, Any]], path: Sequence[str]) -> list[float]:
    """The figure at ``path`` of each of a ``--base`` revision's runs; none if they predate it
    (:class:`MissingFigure`) or did not time it (:class:`PartNotTimed`)."""
    try:
        return _timed_figures(runs, path)
    except MissingFigure:
        return []


def spread(values: Sequence[float]) -> str:
    """``median [min, max]`` (one value: itself; none: ``-``)."""
    if not values:
        return "-"
    if len(values) == 1:
        return f"{values[0]:.1f}"
    return f"{statistics.median(values):.1f} [{min(values):.1f}, {max(values):.1f}]"


def comparison(
    before: dict[str, list[dict[str, Any]]], after: dict[str, list[dict[str, Any]]]
) -> str:
    """The markdown table of ``--base``: per :data:`ROWS` entry and column, the rounds' median
    [min, max] before and after."""
    titles = list(after)
    header = " | ".join(f"{t} before | {t} after" for t in titles)
    lines = [f"| per 1 ms step, units | {header} | target |", "|---" * (2 * len(titles) + 2) + "|"]
    for title, path, target in ROWS:
        cells = [
            spread(values)
            for t in titles
            for values in (_base_figures(before[t], path), _timed_figures(after[t], path))
        ]
        lines.append(
            f"| {title} | " + " | ".join(cells) + f" | {'' if target is None else f'{target:g}'} |"
        )
    units = [r["reference_step_us"] for runs in (before, after) for t in titles for r in runs[t]]
    lines.append("")
    lines.append(f"unit (bare mj_step of Krang-v0): {min(units):.1f} to {max(units):.1f} us")
    disturbed = disturbed_rounds(before, "before ") + disturbed_rounds(after, "after ")
    lines += _disturbed_note(disturbed)
    if any("env_physics" not in r["per_step_units"] for t in titles for r in before[t]):
        lines.append(
            "the base's profiles predate the warm yardstick: their "
            "unit was sampled cold, their floor taken after the control step and their env's own "
            "work counted from it; compare them with these only as ratios within each version"
        )
    return "\n".join(lines)


def _worktree(revision: str, directory: Path) -> None:
    """``revision`` checked out at ``directory``, its compiled code cached there before the
    first timed run (``benchmarks.warm_caches``, if the revision has it): numba's caches live
    beside the sources, and a first run would otherwise compile inside its episode."""
    subprocess.run(
        ["git", "-C", str(REPO), "worktree", "add", "--detach", str(directory), revision],
        check=True,
        capture_output=True,
    )
    if (directory / "benchmarks" / "warm_caches.py").exists():
        subprocess.run(
            [sys.executable, "-m", "benchmarks.warm_caches"],
            check=True,
            stdout=subprocess.DEVNULL,
            cwd=directory,
            env={**os.environ, "PYTHONPATH": str(directory)},
        )


def _runs_in(tree: Path, extra: Sequence[str]) -> bool:
    """Whether ``tree``'s profiler takes the column's arguments: a ``--base`` revision from
    before ``--no-parts`` (066366b) has no such columns (their cells ``-``)."""
    if "--no-parts" not in extra:
        return True
    source = tree / "benchmarks" / "speed" / "profile.py"
    return source.exists() and '"--no-parts"' in source.read_text()


def _remove_worktree(directory: Path) -> None:
    subprocess.run(
        ["git", "-C", str(REPO), "worktree", "remove", "--force", str(directory)],
        check=False,
        capture_output=True,
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=2, help="runs per column (default 2)")
    parser.add_argument("--duration", type=float, default=8.0, help="episode length, s")
    parser.add_argument("--out", type=Path, default=Path("out/perf"), help="the JSON files")
    parser.add_argument("--base", help="a git revision to compare this checkout with")
    args = parser.parse_args(argv)
    if args.rounds < 1 or args.duration <= 0:
        parser.error("--rounds must be >= 1 and --duration > 0")
    args.out.mkdir(parents=True, exist_ok=True)
    trees: dict[str, Path] = {"after": REPO}
    with tempfile.TemporaryDirectory(prefix="wip-gym-base-") as scratch:
        if args.base is not None:
            trees = {"before": Path(scratch) / "tree", "after": REPO}
            try:
                _worktree(args.base, trees["before"])
            except subprocess.CalledProcessError as error:
                parser.error(f"--base {args.base!r}: {error.stderr.decode().strip()}")
        try:
            results: dict[str, dict[str, list[dict[str, Any]]]] = {
                version: {title: [] for title, _, _ in COLUMNS} for version in trees
            }
            runs = [
                (r, version, column)
                for r in range(args.rounds)
                for column in COLUMNS
                for version in trees
                if _runs_in(trees[version], column[2])
            ]
            for r, version, (title, env, extra) in tqdm(runs, desc="profile runs", unit="run"):
                slug = title.lower().replace(", d = ", "_d").replace(",", "").replace(" ", "_")
                path = args.out / f"{version}_{slug}_{r}.json"
                result = _profile(env, extra, args.duration, path, trees[version])
                results[version][title].append(result)
        finally:
            if args.base is not None:
                _remove_worktree(trees["before"])
    if args.base is None:
        print(table(results["after"]))
        if args.rounds > 1:
            print("\nmedian [min, max] over the rounds:\n")
            print(table(results["after"], summary=True))
    else:
        print(comparison(results["before"], results["after"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
