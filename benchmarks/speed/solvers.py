"""``wip-bench solvers``: our solvers against the peers a user would pick instead, on the same
problems, in one process, on this machine.

* DDP on the WIPM (:mod:`benchmarks.speed.ddp_bench`): ours vs crocoddyl (the WIPM as a Python
  action model) vs a NumPy iLQR, the N = 2000 offline plan and the N = 100 warm-started MPC step, on
  the planar and the 3-D model; the optimum checked first on converged solves.
* The whole-body task QP (:mod:`benchmarks.speed.qp_bench`): our ProxQP path vs OSQP, DAQP,
  quadprog and SLSQP on the QPs of a real ``unified`` closed loop on ``PlanarTray-v0`` and
  ``KrangTray-v0``; every solution checked against a KKT-checked reference first.

JSON (``--json PATH``), beyond the details of each half (``ddp``, ``qp``):

* ``ddp_plan_ms``, ``ddp_iter_ms``, ``mpc_step_ms``: ``{planar|3d: {ours|crocoddyl|numpy_ilqr:
  {median, p99}}}`` (milliseconds);
* ``compile_s``: ``{planar|3d: {solver: {plan, mpc}}}``, the first call minus the median, kept
  out of every timing;
* ``qp_solve_us``: ``{planar|krang: {proxqp|proxqp_shortcut|osqp|daqp|quadprog|slsqp:
  {median, p99}}}`` (``proxqp_shortcut``: the controller's own path, the unconstrained
  minimiser when it is feasible, ProxQP otherwise);
* ``ratios``: a peer's median time over ours (above 1: ours is faster): ``crocoddyl_plan_*``,
  ``crocoddyl_mpc_*``, ``numpy_plan_*``, ``numpy_mpc_*`` for ``planar``/``3d`` and
  ``qp_SOLVER_krang``, ``qp_SOLVER_planar`` for each QP peer against ``proxqp``;
* ``ratios_controller_path``: the QP peers' ``qp_SOLVER_ENV`` against ``proxqp_shortcut``;
* ``optimum_checks``: the DDP cost agreement (plan and MPC step) and each QP solver's agreement;
* ``reference_step_us``: the unit (``benchmarks.speed.yardstick``: a bare, warm ``mj_step`` of
  Krang-v0 at its reset state), the median of its timings before and after the DDP half and
  of warm bursts every 50 timed MPC steps (the same load as the steps);
  ``mpc_step_units``: ``{planar|3d: {median, p99}}``, our MPC step in that unit;
* ``targets``: the solver speed targets and the MPC's in units, each ``{figure, limit, met}``
  (:func:`targets`).

    wip-bench solvers [--quick] [--json PATH] [--mpc-steps K]

``--quick`` is a smoke test for CI (a 3 s plan, few steps, a 0.05 s closed loop), not figures.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from benchmarks.speed.ddp_bench import DDPBenchConfig
    from benchmarks.speed.qp_bench import QPBenchConfig

# The peers (the ``bench`` extra) are imported when the command runs, not with the CLI, so
# ``wip-bench compare`` works without them.
PROBLEMS = ("planar", "3d")
SOLVERS = ("ours", "crocoddyl", "numpy_ilqr")
ENVS = ("planar", "krang")
PEER_DISTRIBUTIONS = ("crocoddyl", "proxsuite", "osqp", "daqp", "quadprog", "scipy")
QP_OURS = "proxqp"  # the ratios' reference: ProxQP as the controller configures it
QP_CONTROLLER_PATH = "proxqp_shortcut"  # what the controller runs (unconstrained solve first)
QP_OURS_ALL = (QP_OURS, QP_CONTROLLER_PATH)


def configs(quick: bool) -> tuple[DDPBenchConfig, QPBenchConfig]:
    """The full run's sizes, or ``--quick``'s (a 3 s plan, 10 MPC steps, a 0.05 s loop)."""
    from benchmarks.speed.ddp_bench import DDPBenchConfig  # noqa: PLC0415
    from benchmarks.speed.qp_bench import QPBenchConfig  # noqa: PLC0415

    if not quick:
        return DDPBenchConfig(), QPBenchConfig()
    return (
        DDPBenchConfig(plan_horizon_s=3.0, plan_reps_ours=1, plan_reps_peers=1, mpc_steps=10),
        QPBenchConfig(seconds=0.05, passes=1),
    )


RATIO_DEFINITION = "peer median time / ours (above 1: ours is faster)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``solvers`` subcommand's flags."""
    parser.add_argument(
        "--quick", action="store_true", help="a smoke test for CI (short problems, few steps)"
    )
    parser.add_argument("--json", type=Path, default=None, help="write the results as JSON")
    parser.add_argument(
        "--mpc-steps", type=int, default=None, help="MPC steps timed (default 200, quick 10)"
    )


def _versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for name in ("numpy", "jax", *PEER_DISTRIBUTIONS):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "not installed"
    return out


def _ratio(peer: float | None, ours: float | None) -> float | None:
    if peer is None or ours is None or ours <= 0:
        return None
    return peer / ours


def _target(figure: float | None, limit: float, below: bool = True) -> dict[str, Any]:
    met = None if figure is None else (figure <= limit if below else figure >= limit)
    return {"figure": figure, "limit": limit, "met": met}


def targets(summary: dict[str, Any]) -> dict[str, Any]:
    """The solver speed targets (benchmarks, not tests) against this run's medians: the
    offline plan under 10 ms and 1.5 ms per iteration, the MPC step under 0.3 ms, crocoddyl
    at least 10x slower per solve, the Krang task QP under 40 us and within 2x of the fastest
    peer that agrees."""
    plan, iters, mpc = summary["ddp_plan_ms"], summary["ddp_iter_ms"], summary["mpc_step_ms"]
    ratios = summary["ratios"]
    out: dict[str, Any] = {}
    for p in PROBLEMS:
        out[f"plan_under_10ms_{p}"] = _target(plan[p]["ours"]["median"], 10.0)
        out[f"iteration_under_1.5ms_{p}"] = _target(iters[p]["ours"]["median"], 1.5)
        out[f"mpc_step_under_0.3ms_{p}"] = _target(mpc[p]["ours"]["median"], 0.3)
        for kind in ("plan", "mpc"):
            key = f"crocoddyl_{kind}_{p}"
            out[f"{key}_at_least_10x"] = _target(ratios[key], 10.0, below=False)
    krang = summary["qp_solve_us"]["krang"]
    agreeing = summary["optimum_checks"]["qp"]["krang"]
    peers = [
        entry["median"]
        for name, entry in krang.items()
        if name not in QP_OURS_ALL and agreeing[name]["agree"] and entry["median"] is not None
    ]
    fastest = min(peers) if peers else None
    for suffix, name in (("", QP_OURS), ("_controller_path", QP_CONTROLLER_PATH)):
        ours = krang[name]["median"]
        out[f"qp_krang_under_40us{suffix}"] = _target(ours, 40.0)
        out[f"qp_krang_within_2x_fastest_peer{suffix}"] = _target(
            None if ours is None or fastest is None else ours / fastest, 2.0
        )
    units = summary.get("mpc_step_units")
    if units is not None:
        for p, limit in (("3d", 15.0), ("planar", 8.0)):
            out[f"mpc_step_under_{limit:g}_units_{p}"] = _target(units[p]["median"], limit)
            out[f"mpc_step_p99_under_2x_median_{p}"] = _target(
                units[p]["p99"] / units[p]["median"], 2.0
            )
        out["plan_under_50ms_3d"] = _target(plan["3d"]["ours"]["median"], 50.0)
    return out


def summarise(
    ddp: dict[str, Any], qp: dict[str, Any], unit_us: float | None = None
) -> dict[str, Any]:
    """The top-level schema (module docstring) from the two halves' details and the unit."""
    out: dict[str, Any] = {}
    for key, field in (
        ("ddp_plan_ms", "plan_ms"),
        ("ddp_iter_ms", "iter_ms"),
        ("mpc_step_ms", "mpc_step_ms"),
    ):
        out[key] = {
            p: {s: {q: ddp[p]["solvers"][s][field][q] for q in ("median", "p99")} for s in SOLVERS}
            for p in PROBLEMS
        }
    out["compile_s"] = {
        p: {
            s: {
                "plan": ddp[p]["solvers"][s]["compile_s"],
                "mpc": ddp[p]["solvers"][s]["mpc_compile_s"],
            }
            for s in SOLVERS
        }
        for p in PROBLEMS
    }
    out["qp_solve_us"] = {
        env: {name: dict(entry["solve_us"]) for name, entry in qp[env]["solvers"].items()}
        for env in ENVS
    }
    ratios: dict[str, float | None] = {}
    for p in PROBLEMS:
        for peer, label in (("crocoddyl", "crocoddyl"), ("numpy_ilqr", "numpy")):
            ratios[f"{label}_plan_{p}"] = _ratio(
                out["ddp_plan_ms"][p][peer]["median"], out["ddp_plan_ms"][p]["ours"]["median"]
            )
            ratios[f"{label}_mpc_{p}"] = _ratio(
                out["mpc_step_ms"][p][peer]["median"], out["mpc_step_ms"][p]["ours"]["median"]
            )
    path_ratios: dict[str, float | None] = {}
    for env in ENVS:
        times = out["qp_solve_us"][env]
        for name in times:
            if name in QP_OURS_ALL:
                continue
            ratios[f"qp_{name}_{env}"] = _ratio(times[name]["median"], times[QP_OURS]["median"])
            path_ratios[f"qp_{name}_{env}"] = _ratio(
                times[name]["median"], times[QP_CONTROLLER_PATH]["median"]
            )
    out["ratios"] = ratios
    out["ratios_controller_path"] = path_ratios
    if unit_us is not None:
        out["reference_step_us"] = unit_us
        out["mpc_step_units"] = {
            p: {q: out["mpc_step_ms"][p]["ours"][q] * 1e3 / unit_us for q in ("median", "p99")}
            for p in PROBLEMS
        }
    out["ratio_definition"] = RATIO_DEFINITION
    out["optimum_checks"] = {
        "ddp": {
            p: {
                what: {k: check[k] for k in ("max_rel_diff", "tolerance", "agree", "costs")}
                for what, check in ddp[p]["optimum_check"].items()
            }
            for p in PROBLEMS
        },
        "qp": {
            env: {
                name: {
                    k: entry[k]
                    for k in ("max_error", "agree", "failures", "first_failure", "stalled")
                }
                for name, entry in qp[env]["solvers"].items()
            }
            for env in ENVS
        },
    }
    out["targets"] = targets(out)
    return out


def run_benchmark(quick: bool = False, mpc_steps: int | None = None) -> dict[str, Any]:
    """All measurements as one JSON-ready dictionary."""
    try:
        from benchmarks.speed import ddp_bench, qp_bench  # noqa: PLC0415
    except ImportError as error:
        raise ValueError(
            f"wip-bench solvers needs the peers: pip install -c constraints.txt -e '.[bench]' "
            f"({error})"
        ) from error
    ddp_config, qp_config = configs(quick)
    if mpc_steps is not None:
        if mpc_steps < 1:
            raise ValueError(f"--mpc-steps must be >= 1, got {mpc_steps}")
        ddp_config = dataclasses.replace(ddp_config, mpc_steps=mpc_steps)
    machine = {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "load_average_1min_at_start": os.getloadavg()[0],
    }
    from benchmarks.speed.yardstick import reference_step_samples  # noqa: PLC0415

    unit_before = reference_step_samples()
    ddp_bench.REFERENCE_SAMPLES.clear()
    ddp = ddp_bench.run(ddp_config)
    bursts = np.array(ddp_bench.REFERENCE_SAMPLES)
    unit_after = reference_step_samples()
    qp = qp_bench.run(qp_config)
    machine["load_average_1min_at_end"] = os.getloadavg()[0]
    unit_us = float(np.median(np.concatenate([unit_before, bursts, unit_after])) * 1e6)
    return {
        "command": "wip-bench solvers" + (" --quick" if quick else ""),
        "quick": quick,
        "machine": machine,
        "versions": _versions(),
        **summarise(ddp, qp, unit_us),
        "ddp": ddp,
        "qp": qp,
    }


def _f(value: float | None, spec: str) -> str:
    return "n/a" if value is None else format(value, spec)


def format_table(results: dict[str, Any]) -> str:
    """Plain-text tables of the results (Markdown-compatible)."""
    ddp, ratios = results["ddp"], results["ratios"]
    lines = [
        f"$ {results['command']}",
        "",
        "| problem | solver | plan (ms) | iters | per iter (ms) | MPC median (ms) | "
        "MPC p99 (ms) | compile plan/MPC (s) | plan cost |",
        "|" + "---|" * 9,
    ]
    for p in PROBLEMS:
        for s in SOLVERS:
            r = ddp[p]["solvers"][s]
            lines.append(
                f"| {p} | {s} | {r['plan_ms']['median']:.1f} | {r['plan_iterations']} | "
                f"{r['iter_ms']['median']:.2f} | {r['mpc_step_ms']['median']:.3f} | "
                f"{r['mpc_step_ms']['p99']:.3f} | {r['compile_s']:.1f}/{r['mpc_compile_s']:.1f} "
                f"| {r['plan_cost']:.10g} |"
            )
    lines.append("")
    if "mpc_step_units" in results:
        units = results["mpc_step_units"]
        lines.append(
            f"unit: a bare mj_step of Krang-v0 at its reset state, "
            f"{results['reference_step_us']:.1f} us; our MPC step: "
            + ", ".join(
                f"{p} median {units[p]['median']:.1f} units, p99 {units[p]['p99']:.1f}"
                for p in PROBLEMS
            )
        )
    for p in PROBLEMS:
        checks = ddp[p]["optimum_check"]
        lines.append(
            f"{p}: N = {ddp[p]['plan_steps']}, MPC N = {ddp[p]['mpc_horizon']} at "
            f"{ddp[p]['mpc_iterations']} iterations; converged costs agree (max relative "
            f"difference: plan {checks['plan']['max_rel_diff']:.1e}, MPC step "
            f"{checks['mpc_step']['max_rel_diff']:.1e}; tolerance {checks['plan']['tolerance']:g})"
        )
    lines += [
        "",
        "| env | solver | median (us) | p99 (us) | max error | agrees (1e-6) | failures | "
        "stalled |",
        "|" + "---|" * 8,
    ]
    for env in ENVS:
        entry = results["qp"][env]
        for name, r in entry["solvers"].items():
            lines.append(
                f"| {env} | {name} | {_f(r['solve_us']['median'], '.1f')} | "
                f"{_f(r['solve_us']['p99'], '.1f')} | {_f(r['max_error'], '.1e')} | "
                f"{'yes' if r['agree'] else 'NO'} | {r['failures']} | {r['stalled']} |"
            )
    lines.append("")
    for env in ENVS:
        entry = results["qp"][env]
        lines.append(
            f"{env}: {entry['qps']} QPs from {entry['seconds']} s of `unified` on "
            f"{entry['env']} ({entry['variables']} variables, {entry['constraints']} "
            f"constraints, {entry['qps_with_active_constraints']} with active constraints), "
            f"{entry['passes']} passes"
        )
    lines.append(
        "stalled: solves that ended at the solver's precision limit (SLSQP exit mode 8), "
        "their solutions checked like any other; the reference: quadprog's, KKT-checked"
    )
    lines.append("")
    lines.append(
        "Targets: "
        + "; ".join(
            f"{key} {_f(t['figure'], '.3g')}: "
            + {True: "met", False: "NOT met", None: "n/a"}[t["met"]]
            for key, t in results["targets"].items()
        )
    )
    lines.append("")
    lines.append(
        f"Ratios ({RATIO_DEFINITION}): "
        + ", ".join(f"{key} {_f(value, '.2f')}" for key, value in ratios.items())
    )
    return "\n".join(lines)


def run(args: argparse.Namespace) -> None:
    """The ``solvers`` subcommand."""
    results = run_benchmark(quick=args.quick, mpc_steps=args.mpc_steps)
    print(format_table(results))
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2))
        print(f"wrote {args.json}")
