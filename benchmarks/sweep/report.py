"""The sweep's report: ``DIR/summary.json``, ``DIR/report.md`` and the plots, from the spec and
the store (so it is the same whether written at the end of a run or on demand)."""

from __future__ import annotations

import itertools
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from benchmarks.metrics import outcome_counts
from benchmarks.sweep.frontier import frontier_rows, value_label
from benchmarks.sweep.keys import spec_keys_not_applied
from benchmarks.sweep.spec import SweepSpec
from benchmarks.sweep.stats import (
    describe,
    paired_mean_difference,
    paired_success_difference,
    rate,
    wilson_interval,
)
from benchmarks.sweep.store import latest_rows, read_rows

SPEC_NAME = "spec.toml"
# Per-episode metrics summarised per controller and compared between controllers.
STAT_METRICS = (
    "max_cup_friction_use",
    "cup_friction_use_p99",
    "max_tray_tilt_deg",
    "cup_slip_distance_m",
    "slipping_time_s",
    "time_to_goal_s",
)


def _values(rows: list[dict[str, Any]], metric: str) -> list[float]:
    return [r["metrics"][metric] for r in rows if r["metrics"].get(metric) is not None]


def _flag_rate(rows: list[dict[str, Any]], flag: str) -> tuple[float | None, list[float] | None]:
    """The rate of ``flag`` over the rows that report it (``carried`` is None without a tray)
    and its Wilson 95 % interval; (None, None) when none does."""
    stat = rate([r["metrics"].get(flag) for r in rows])
    return (None, None) if stat is None else (stat["rate"], stat["ci95"])


def _controller_summary(rows: list[dict[str, Any]], failed: int) -> dict[str, Any]:
    n = len(rows)
    successes = sum(1 for r in rows if r["metrics"].get("success"))
    carried, carried_ci = _flag_rate(rows, "carried")
    goal, goal_ci = _flag_rate(rows, "goal_reached")
    return {
        "n": n,
        "n_failed": failed,
        "success_rate": successes / n if n else None,
        "success_ci95": list(wilson_interval(successes, n)) if n else None,
        "carried_rate": carried,
        "carried_ci95": carried_ci,
        "goal_reached_rate": goal,
        "goal_reached_ci95": goal_ci,
        "outcomes": outcome_counts([r["metrics"] for r in rows]),
        "stats": {metric: describe(_values(rows, metric)) for metric in STAT_METRICS},
    }


def _paired_rate(a: list[dict[str, Any]], b: list[dict[str, Any]], flag: str) -> Any:
    """The paired difference of ``flag``'s rates over the pairs that both report it."""
    pairs = [
        (bool(x[flag]), bool(y[flag]))
        for x, y in zip(a, b, strict=True)
        if x.get(flag) is not None and y.get(flag) is not None
    ]
    if not pairs:
        return None
    estimate, interval = paired_success_difference([p[0] for p in pairs], [p[1] for p in pairs])
    return {"n": len(pairs), "estimate": estimate, "ci95": list(interval)}


def _paired(
    a_name: str, b_name: str, a_rows: dict[int, dict[str, Any]], b_rows: dict[int, dict[str, Any]]
) -> dict[str, Any] | None:
    replicates = sorted(set(a_rows) & set(b_rows))
    if not replicates:
        return None
    a = [a_rows[k]["metrics"] for k in replicates]
    b = [b_rows[k]["metrics"] for k in replicates]
    estimate, interval = paired_success_difference(
        [bool(m.get("success")) for m in a], [bool(m.get("success")) for m in b]
    )
    paired: dict[str, Any] = {
        "a": a_name,
        "b": b_name,
        "n": len(replicates),
        "success_rate_difference": {"estimate": estimate, "ci95": list(interval)},
        "carried_rate_difference": _paired_rate(a, b, "carried"),
    }
    for metric in STAT_METRICS:
        pairs = [
            (x[metric], y[metric])
            for x, y in zip(a, b, strict=True)
            if x.get(metric) is not None and y.get(metric) is not None
        ]
        if not pairs:
            paired[f"{metric}_difference"] = None
            continue
        mean, ci = paired_mean_difference([p[0] for p in pairs], [p[1] for p in pairs])
        paired[f"{metric}_difference"] = {
            "n": len(pairs),
            "mean": mean,
            "ci95": list(ci) if ci is not None else None,
        }
    return paired


def build_summary(
    spec: SweepSpec, run: Mapping[str, Any] | None, directory: str | Path
) -> dict[str, Any]:
    """The summary of every planned episode's latest row in the store; ``run`` holds this
    invocation's counts (``episodes_run``, ``episodes_skipped``, wall time; None on demand)."""
    episodes = spec.episodes()
    latest = latest_rows(read_rows(directory))
    planned = {e.id for e in episodes}
    rows = {e.id: latest[e.id] for e in episodes if e.id in latest}
    ok = {i: r for i, r in rows.items() if r["status"] == "ok"}
    commits = sorted(
        {str(r.get("git_commit")) + ("-dirty" if r.get("git_dirty") else "") for r in rows.values()}
    )
    cells = []
    by_cell: dict[int, list[Any]] = {}
    for e in episodes:
        by_cell.setdefault(e.cell_index, []).append(e)
    for index, cell in enumerate(spec.cells()):
        mine = by_cell.get(index, [])
        controllers: dict[str, Any] = {}
        per_replicate: dict[str, dict[int, dict[str, Any]]] = {}
        for name in spec.controllers:
            ids = [e for e in mine if e.controller == name]
            done = [ok[e.id] for e in ids if e.id in ok]
            failed = sum(1 for e in ids if e.id in rows and rows[e.id]["status"] != "ok")
            controllers[name] = _controller_summary(done, failed)
            per_replicate[name] = {ok[e.id]["replicate"]: ok[e.id] for e in ids if e.id in ok}
        paired = [
            p
            for a, b in itertools.combinations(spec.controllers, 2)
            if (p := _paired(a, b, per_replicate[a], per_replicate[b])) is not None
        ]
        cells.append({"parameters": cell, "controllers": controllers, "paired": paired})
    run = dict(run or {})
    return {
        "engine": "ray",
        "env": spec.env,
        "preset": spec.preset,
        "controllers": list(spec.controllers),
        "duration_s": spec.duration,
        "seeds": spec.seeds,
        "seed": spec.seed,
        "set": spec.base,
        "grid": {k: list(v) for k, v in spec.grid.items()},
        "random": {k: d.as_json() for k, d in spec.random.items()},
        "episodes_total": len(episodes),
        "episodes_run": run.get("episodes_run", 0),
        "episodes_skipped": run.get("episodes_skipped", 0),
        "episodes_failed": sum(1 for r in rows.values() if r["status"] != "ok"),
        "episodes_ok": len(ok),
        "episodes_missing": len(planned) - len(rows),
        "rows_outside_spec": sum(1 for i in latest if i not in planned),
        "wall_s": run.get("wall_s"),
        "episodes_per_hour": run.get("episodes_per_hour"),
        "interrupted": bool(run.get("interrupted", False)),
        "keys_not_applied": {k: list(v) for k, v in spec_keys_not_applied(spec).items()},
        "commits": commits,
        "mixed_commits": len(commits) > 1,
        "package_versions": sorted({str(r.get("package_version")) for r in rows.values()}),
        "cells": cells,
        "frontier": frontier_rows(spec, cells),
    }


def _fmt(value: Any, spec: str = ".3f") -> str:
    return "-" if value is None else format(value, spec)


def _cell_label(parameters: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={json.dumps(v)}" for k, v in parameters.items()) or "(one cell)"


def format_markdown(summary: Mapping[str, Any], plots: list[str]) -> str:
    lines = [
        f"# Sweep: {summary['env']}",
        "",
        f"Controllers {', '.join(summary['controllers'])}; {summary['seeds']} seeds per cell "
        f"(sweep seed {summary['seed']}); {summary['duration_s']} s per episode"
        + (f"; preset {summary['preset']}" if summary["preset"] else "")
        + ".",
        f"Base overrides: `{json.dumps(summary['set'])}`; "
        f"random: `{json.dumps(summary['random'])}`.",
        "",
        f"Episodes: {summary['episodes_total']} planned, {summary['episodes_ok']} ok, "
        f"{summary['episodes_failed']} failed, {summary['episodes_missing']} missing; this run "
        f"ran {summary['episodes_run']} and skipped {summary['episodes_skipped']}"
        + (
            f" ({summary['episodes_per_hour']:.0f} episodes per hour)"
            if summary["episodes_per_hour"]
            else ""
        )
        + ".",
    ]
    for key, left in summary["keys_not_applied"].items():
        lines += ["", f"`{key}` leaves {', '.join(left)} as configured (no offline plan)."]
    if summary["mixed_commits"]:
        lines += [
            "",
            f"**Warning: rows from more than one commit are mixed: "
            f"{', '.join(summary['commits'])}.**",
        ]
    lines += [
        "",
        "Carried rate (the cup carried to the end: docs/metrics.md §1), success rate (carried "
        "and at the goal) and goal-reached rate, each with its 95 % Wilson interval; the "
        "episodes per outcome; peak friction use, peak tray tilt (deg), cup slip distance (m) "
        "and time to goal (s) as mean ± std over the episodes that ran.",
        "",
        "| cell | controller | n | failed | carried | 95 % CI | success | 95 % CI | goal "
        "| 95 % CI | outcomes | friction use | tilt deg | slip m | time to goal s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]

    def ms(stat: Any) -> str:
        return "-" if stat is None else f"{stat['mean']:.3f} ± {stat['std']:.3f}"

    def interval(ci: Any) -> str:
        return "-" if ci is None else f"[{ci[0]:.2f}, {ci[1]:.2f}]"

    for cell in summary["cells"]:
        label = _cell_label(cell["parameters"])
        for name, c in cell["controllers"].items():
            s = c["stats"]
            outcomes = ", ".join(f"{kind} {n}" for kind, n in c["outcomes"].items()) or "-"
            lines.append(
                f"| {label} | {name} | {c['n']} | {c['n_failed']} "
                f"| {_fmt(c['carried_rate'], '.2f')} | {interval(c['carried_ci95'])} "
                f"| {_fmt(c['success_rate'], '.2f')} | {interval(c['success_ci95'])} "
                f"| {_fmt(c['goal_reached_rate'], '.2f')} | {interval(c['goal_reached_ci95'])} "
                f"| {outcomes} "
                f"| {ms(s['max_cup_friction_use'])} | {ms(s['max_tray_tilt_deg'])} "
                f"| {ms(s['cup_slip_distance_m'])} | {ms(s['time_to_goal_s'])} |"
            )
    lines += _frontier_markdown(summary["frontier"])
    lines += [
        "",
        "## Paired differences (a - b on the same seeds)",
        "",
        "Carried and success rates: Newcombe's interval for paired proportions; peak friction "
        "use: mean difference with Student's t interval.",
        "",
        "| cell | a | b | pairs | carried a - b | 95 % CI | success a - b | 95 % CI "
        "| friction use a - b | 95 % CI |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for cell in summary["cells"]:
        label = _cell_label(cell["parameters"])
        for p in cell["paired"]:
            c = p["carried_rate_difference"]
            cci = None if c is None else c["ci95"]
            s = p["success_rate_difference"]
            f = p["max_cup_friction_use_difference"]
            fci = None if f is None else f["ci95"]
            lines.append(
                f"| {label} | {p['a']} | {p['b']} | {p['n']} "
                f"| {'-' if c is None else format(c['estimate'], '+.2f')} "
                f"| {'-' if cci is None else f'[{cci[0]:+.2f}, {cci[1]:+.2f}]'} "
                f"| {s['estimate']:+.2f} "
                f"| [{s['ci95'][0]:+.2f}, {s['ci95'][1]:+.2f}] "
                f"| {'-' if f is None else format(f['mean'], '+.3f')} "
                f"| {'-' if fci is None else f'[{fci[0]:+.3f}, {fci[1]:+.3f}]'} |"
            )
    if plots:
        lines += ["", "## Plots", ""] + [f"![{p}]({p})" for p in plots]
    return "\n".join(lines) + "\n"


def _frontier_markdown(rows: list[dict[str, Any]]) -> list[str]:
    """The frontier table (nothing without a ``[[frontier]]``)."""
    if not rows:
        return []
    lines = [
        "",
        "## Frontiers",
        "",
        "Critical value: along the axis, the hardest value at which the carried rate is at "
        "least the rate there and at every easier value; `-` when even the easiest falls short "
        "(docs/sweeps.md §5). The axis is ordered as listed in the grid; harder toward `low` is "
        "toward the first listed value. Carried rates in the listed order.",
        "",
        "| axis | harder toward | rate | fixed | controller | critical | carried rates |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        rates = ", ".join(f"{value}: {_fmt(r, '.2f')}" for value, r in row["rates"].items())
        critical = "-" if row["critical"] is None else value_label(row["critical"])
        lines.append(
            f"| {row['axis']} | {row['toward']} | {row['rate']:.2f} "
            f"| {_cell_label(row['fixed']) if row['fixed'] else '-'} | {row['controller']} "
            f"| {critical} | {rates} |"
        )
    return lines


def write_report(
    spec: SweepSpec, directory: str | Path, run: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """Write ``summary.json``, ``report.md`` and the plots into ``directory``."""
    from benchmarks.sweep.plots import write_plots

    directory = Path(directory)
    summary = build_summary(spec, run, directory)
    with open(directory / "summary.json", "w") as f:
        json.dump(summary, f, indent=2)
    plots = write_plots(spec, summary, directory)
    (directory / "report.md").write_text(format_markdown(summary, plots))
    return summary


def report_directory(directory: str | Path) -> dict[str, Any]:
    """The report of a sweep directory on demand, from its saved spec and its store."""
    from benchmarks.sweep.spec import SpecError, parse_spec

    path = Path(directory) / SPEC_NAME
    if not path.exists():
        raise SpecError(f"{directory} holds no sweep ({SPEC_NAME} not found)")
    return write_report(parse_spec(path.read_text(), validate_env=False), directory)
