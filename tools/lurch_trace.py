"""Where in a drive each controller comes closest to slipping the cup: the backward lurch at
the start (the WIP rolls back to lean forward: non-minimum phase) against the rest.

    python -m tools.lurch_trace --env wip_gym/PlanarTray-v0 --goal 2 --duration 8 \
        --a-max 2.5 --q-position 100 --theta-max 0.3

Every controller gets the same offline plan settings (the flags set ``plan.a_max``,
``plan.q_position`` and ``plan.theta_max``, the keys of ``wip-bench compare --set``; ``--set``
and ``--preset`` take any other key). The episodes run through the benchmark's one rollout
(``benchmarks.rollout``), so the cup's metrics are the benchmark's. Per controller (seed 0,
nominal models, one episode each, sequentially): the plan's peak acceleration, how far the
axle rolls back, when it is back at its start (the lurch's end), the peak cup friction use
and tray tilt during the lurch and after it, and whether the cup stayed on the tray.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from benchmarks.overrides import parse_assignment, resolve_run
from benchmarks.presets import add_configuration_arguments
from benchmarks.rollout import rollout
from benchmarks.scenario import resolve_env_id


def trace(
    env_id: str,
    controller: str,
    goal: float,
    friction: float,
    seconds: float,
    overrides: dict[str, Any],
    preset: str | None = None,
) -> dict:
    """One episode (seed 0) of ``controller``; the lurch's numbers and the time series."""
    spec = resolve_run(
        env_id, [controller], preset, {"goal": goal, "cup_friction": friction}, {}, overrides
    )
    rows: list[tuple[float, ...]] = []

    def record(env: Any, info: dict[str, Any], step_index: int) -> None:
        if step_index > 0:
            rows.append(
                (
                    step_index * env.unwrapped.dt,
                    info["x"],
                    info["xd"],
                    info["cup_friction_use"],
                    info["tray_tilt_deg"],
                )
            )

    episode = rollout(
        env_id, spec.env_kwargs, controller, spec.configs[controller], 0, seconds, on_step=record
    )
    policy = episode.policy
    t, x, xd, friction_use, tilt = np.array(rows).T
    back = np.flatnonzero((x > 0.0) & (t > t[np.argmin(x)]))
    end = int(back[0]) if len(back) else len(t) - 1
    lurch, rest = slice(0, end + 1), slice(end + 1, len(t))
    return {
        "controller": controller,
        "plan_peak_a": float(policy.plan.peak_acceleration),
        "plan_violations": policy.plan.violations,
        "roll_back_cm": -100.0 * float(x.min()),
        "lurch_end_s": float(t[end]),
        "lurch_friction": float(friction_use[lurch].max()),
        "lurch_friction_at_s": float(t[lurch][np.argmax(friction_use[lurch])]),
        "lurch_tilt_deg": float(tilt[lurch].max()),
        "rest_friction": float(friction_use[rest].max()) if end + 1 < len(t) else float("nan"),
        "rest_tilt_deg": float(tilt[rest].max()) if end + 1 < len(t) else float("nan"),
        "peak_speed": float(xd.max()),
        "cup_kept": bool(episode.metrics["cup_kept"]),
        "series": np.array(rows),
    }


def print_series(series: np.ndarray, start: float, stop: float, every: float) -> None:
    """Rows of the time series: the axle's acceleration as the mean over 20 ms of the speed's
    differences, and the tray tilt that would cancel it, ``atan(a / g)``."""
    t, x, xd, friction_use, tilt = series.T
    dt = t[1] - t[0]
    window = max(1, int(round(0.02 / dt)))
    a = np.convolve(np.gradient(xd, dt), np.ones(window) / window, mode="same")
    print("| t s | x m | xd m/s | axle a m/s^2 | atan(a/g) deg | tray tilt deg | friction use |")
    print("|---|---|---|---|---|---|---|")
    step = max(1, int(round(every / dt)))
    for i in range(0, len(t), step):
        if start <= t[i] <= stop + 1e-9:
            print(
                f"| {t[i]:.2f} | {x[i]:.3f} | {xd[i]:.2f} | {a[i]:.2f} | "
                f"{np.degrees(np.arctan(a[i] / 9.81)):.1f} | {tilt[i]:.1f} | "
                f"{friction_use[i]:.2f} |"
            )


def main() -> None:
    from controllers.optimizer import jax_setup

    jax_setup.configure()  # the solvers' JAX settings, before JAX starts
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="wip_gym/PlanarTray-v0")
    parser.add_argument("--goal", type=float, default=2.0)
    parser.add_argument("--cup-friction", type=float, default=0.3)
    parser.add_argument("--duration", type=float, default=8.0)
    parser.add_argument("--controllers", default="decoupled,decoupled-mpc,unified,unified-waiter")
    parser.add_argument("--a-max", type=float, help="plan.a_max, m/s^2 (default: cup-safe)")
    parser.add_argument("--q-position", type=float, help="plan.q_position")
    parser.add_argument("--theta-max", type=float, help="plan.theta_max, rad")
    add_configuration_arguments(parser, set_help="a wip-bench compare --set key")
    parser.add_argument("--trace", default="", help="controllers whose time series to print")
    parser.add_argument("--window", default="0:2", help="START:STOP s of the time series")
    parser.add_argument("--every", type=float, default=0.05, help="s between rows")
    args = parser.parse_args()
    env_id = resolve_env_id(args.env)
    overrides = {
        f"plan.{name}": value
        for name, value in (
            ("a_max", args.a_max),
            ("q_position", args.q_position),
            ("theta_max", args.theta_max),
        )
        if value is not None
    }
    overrides.update(parse_assignment(text) for text in args.overrides)
    header = (
        "controller",
        "plan peak a",
        "roll back cm",
        "lurch ends s",
        "lurch: friction (at s)",
        "lurch: tilt deg",
        "after: friction",
        "after: tilt deg",
        "peak xd",
        "cup kept",
    )
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for name in args.controllers.split(","):
        r = trace(env_id, name, args.goal, args.cup_friction, args.duration, overrides, args.preset)
        if r["plan_violations"]:
            print(f"plan violations: {r['plan_violations']}")
        print(
            f"| {name} | {r['plan_peak_a']:.2f} | {r['roll_back_cm']:.1f} | "
            f"{r['lurch_end_s']:.2f} | "
            f"{r['lurch_friction']:.2f} ({r['lurch_friction_at_s']:.2f}) | "
            f"{r['lurch_tilt_deg']:.1f} | {r['rest_friction']:.2f} | {r['rest_tilt_deg']:.1f} | "
            f"{r['peak_speed']:.2f} | {'yes' if r['cup_kept'] else 'no'} |",
            flush=True,
        )
        if name in args.trace.split(","):
            start, stop = (float(v) for v in args.window.split(":"))
            print(f"\n{name}:")
            print_series(r["series"], start, stop, args.every)
            print()


if __name__ == "__main__":
    main()
