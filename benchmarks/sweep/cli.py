"""``wip-bench sweep``: run a sweep spec on Ray, or report on a sweep directory.

wip-bench sweep SPEC --out DIR [--address ADDRESS] [--workers N]
wip-bench sweep SPEC --dry-run [--out DIR] [--workers N] [--no-calibration]
wip-bench sweep --report DIR

Exit status: 0 when every planned episode has an ``ok`` row; 1 when some failed (their rows,
the summary and the report are written first; the rows hold the tracebacks); 130 after Ctrl-C;
2 for a bad spec or bad arguments, before anything runs.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from benchmarks.sweep import estimate
from benchmarks.sweep.keys import spec_keys_not_applied
from benchmarks.sweep.spec import SpecError, SweepSpec, load_spec


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
        "--no-calibration",
        action="store_true",
        help="--dry-run without its calibration episodes (and so without a time estimate "
        "unless --out holds finished episodes)",
    )
    parser.add_argument(
        "--report", metavar="DIR", help="write the report of a sweep directory and exit"
    )


def frontier_lines(spec: SweepSpec) -> list[str]:
    """The frontiers as the report will compute them: each axis from easiest to hardest."""
    lines = []
    for f in spec.frontiers:
        per_controller = len(spec.cells()) // len(spec.grid[f.axis])
        order = " -> ".join(json.dumps(v) for v in f.easiest_first(spec.grid[f.axis]))
        lines.append(
            f"  frontier {f.axis}: carried rate >= {f.rate:g}, harder toward {f.toward} "
            f"(easiest to hardest: {order}); {per_controller * len(spec.controllers)} rows "
            f"(controllers x combinations of the other axes)"
        )
    return lines


def dry_run(
    spec: SweepSpec, directory: str | None, workers: int | None, calibrate: bool = True
) -> None:
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
    for line in frontier_lines(spec):
        print(line)
    for key, left in spec_keys_not_applied(spec).items():
        print(f"  {key} leaves {', '.join(left)} as configured (no offline plan)")
    todo = spec.episodes()
    if directory and Path(directory).exists():
        todo, skipped, _ = plan_run(spec, directory)
        print(f"{skipped} episodes already in {directory} would be skipped")
    n_workers = workers or os.cpu_count() or 1
    measured = (
        estimate.from_rows(len(todo), n_workers, directory)
        if directory and Path(directory).exists()
        else None
    )
    if measured is None and calibrate:
        measured = estimate.from_calibration(spec, todo, estimate.calibrate(spec), n_workers)
    if measured is None:
        print(
            f"{len(todo)} episodes to run on {n_workers} workers (no time estimate: "
            f"--no-calibration and no finished episodes in --out)"
        )
        return
    seconds, how = measured
    for line in how:
        print(line)
    print(
        f"{len(todo)} episodes to run on {n_workers} workers: about {seconds / 60:.0f} min "
        f"({seconds / 3600:.1f} h; with a core per worker, after each worker's start; less "
        f"where episodes end early)"
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
        dry_run(spec, args.out, args.workers, calibrate=not args.no_calibration)
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
