"""``wip-bench sweep``: run a sweep spec on Ray, or report on a sweep directory.

wip-bench sweep SPEC --out DIR [--address ADDRESS] [--workers N]
wip-bench sweep SPEC --dry-run [--out DIR] [--workers N]
wip-bench sweep --report DIR

Exit status: 0 when every planned episode has an ``ok`` row; 1 when some failed (their rows,
the summary and the report are written first; the rows hold the tracebacks); 130 after Ctrl-C;
2 for a bad spec or bad arguments, before anything runs.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
from pathlib import Path

from benchmarks.sweep.keys import spec_keys_not_applied
from benchmarks.sweep.spec import SpecError, SweepSpec, load_spec
from benchmarks.sweep.store import read_rows

# --dry-run's time estimate when the directory has no measured episodes: seconds of setup per
# episode (env and controller construction, the offline plan) and a real-time factor of the
# closed loop, both on the cautious side of what PlanarTray-v0 and KrangTray-v0 measure here.
ASSUMED_SETUP_S = 2.0
ASSUMED_REAL_TIME_FACTOR = 0.5


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("spec", nargs="?", help="the sweep's TOML spec")
    parser.add_argument("--out", metavar="DIR", help="the sweep's directory (store and report)")
    parser.add_argument("--address", help="join this Ray cluster (default: a local one)")
    parser.add_argument(
        "--workers", type=int, help="episodes in flight (default: the cluster's CPUs)"
    )
    parser.add_argument(
        "--dry-run", action="store_true", help="print the cells, episode count, time estimate"
    )
    parser.add_argument(
        "--report", metavar="DIR", help="write the report of a sweep directory and exit"
    )


def estimate_seconds(
    spec: SweepSpec, episodes: int, workers: int, directory: str | None
) -> tuple[float, str]:
    """Wall time of ``episodes`` on ``workers``: measured per-episode wall time in the
    directory if it has rows, else the assumed setup and real-time factor."""
    rows = read_rows(directory) if directory else []
    walls = [r["wall_s"] for r in rows if r.get("status") == "ok"]
    if walls:
        per_episode = statistics.fmean(walls)
        source = f"measured: mean {per_episode:.1f} s over {len(walls)} episodes in {directory}"
    else:
        per_episode = ASSUMED_SETUP_S + spec.duration / ASSUMED_REAL_TIME_FACTOR
        source = (
            f"assumed: {ASSUMED_SETUP_S:.0f} s setup + real-time factor "
            f"{ASSUMED_REAL_TIME_FACTOR} per episode"
        )
    return episodes * per_episode / max(1, workers), source


def dry_run(spec: SweepSpec, directory: str | None, workers: int | None) -> None:
    from benchmarks.sweep.runner import plan_run

    cells = spec.cells()
    print(
        f"{spec.env}: {len(cells)} cells x {len(spec.controllers)} controllers x "
        f"{spec.seeds} seeds = {len(cells) * len(spec.controllers) * spec.seeds} episodes "
        f"of {spec.duration} s"
    )
    for index, cell in enumerate(cells):
        print(
            f"  cell {index:>3}: "
            + (", ".join(f"{k}={json.dumps(v)}" for k, v in cell.items()) or "(no grid)")
        )
    if spec.random:
        print(
            "  random per episode: "
            + ", ".join(f"{k} ~ {json.dumps(d.as_json())}" for k, d in spec.random.items())
        )
    for key, left in spec_keys_not_applied(spec).items():
        print(f"  {key} leaves {', '.join(left)} as configured (no offline plan)")
    todo = len(spec.episodes())
    if directory and Path(directory).exists():
        episodes, skipped, _ = plan_run(spec, directory)
        todo = len(episodes)
        print(f"{skipped} episodes already in {directory} would be skipped")
    n_workers = workers or os.cpu_count() or 1
    seconds, source = estimate_seconds(spec, todo, n_workers, directory)
    print(
        f"{todo} episodes to run on {n_workers} workers: about {seconds / 60:.0f} min "
        f"({seconds / 3600:.1f} h; {source})"
    )


def run(args: argparse.Namespace) -> int:
    """The subcommand; ValueError (exit status 2) for a bad spec or bad arguments."""
    if args.report:
        if args.spec:
            raise SpecError("--report DIR takes no SPEC")
        from benchmarks.sweep.report import report_directory

        summary = report_directory(args.report)
        print(
            f"wrote {Path(args.report) / 'summary.json'} and "
            f"{Path(args.report) / 'report.md'} ({summary['episodes_ok']} ok, "
            f"{summary['episodes_failed']} failed, {summary['episodes_missing']} missing)"
        )
        return 0
    if not args.spec:
        raise SpecError("give a SPEC (or --report DIR)")
    if args.workers is not None and args.workers < 1:
        raise SpecError(f"--workers must be >= 1, got {args.workers}")
    spec = load_spec(args.spec)
    if args.dry_run:
        dry_run(spec, args.out, args.workers)
        return 0
    if not args.out:
        raise SpecError("--out DIR is required to run a sweep")
    from benchmarks.sweep.runner import run_sweep

    summary = run_sweep(
        spec,
        args.out,
        address=args.address,
        workers=args.workers,
        imports=getattr(args, "imports", ()),
    )
    if summary["interrupted"]:
        return 130
    if summary["episodes_failed"]:
        print(
            f"{summary['episodes_failed']} episodes failed: their rows in "
            f"{Path(args.out) / 'episodes.jsonl'} hold the tracebacks; run the same command "
            "again to retry them"
        )
        return 1
    return 0
