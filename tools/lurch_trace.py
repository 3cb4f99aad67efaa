"""Where in a drive each controller comes closest to slipping the cup: the backward lurch at
the start (the WIP rolls back to lean forward: non-minimum phase) against the rest.

    python -m tools.lurch_trace --env wip_gym/PlanarTray-v0 --goal 2 --duration 8 \
        --a-max 2.5 --q-position 100 --theta-max 0.3

Every controller gets the same offline plan settings (``PlanConfig``; the flags change
``a_max``, the running weight on position and ``theta_max`` from their defaults: a faster plan,
the one knob ``wip-bench compare`` does not expose). Per controller (seed 0, nominal models,
one episode each, sequentially): the plan's peak acceleration, how far the axle rolls back,
when it is back at its start (the lurch's end), the peak cup friction use and tray tilt
during the lurch and after it, and whether the cup stayed on the tray.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import wip_gym  # noqa: F401
from controllers.decoupled import DecoupledConfig, DecoupledController
from controllers.decoupled_mpc import DecoupledMPCConfig, DecoupledMPCController
from controllers.hierarchical import HierarchicalConfig, HierarchicalController
from controllers.high_level import HighLevelConfig
from controllers.planning import PlanConfig


def make_policy(name: str, env: gym.Env, plan: PlanConfig):  # noqa: ANN201
    """The benchmark's controller ``name`` with the plan settings ``plan``."""
    if name == "decoupled":
        return DecoupledController.for_env(env, DecoupledConfig(plan=plan))
    high_level = HighLevelConfig(plan=plan)
    if name == "decoupled-mpc":
        return DecoupledMPCController.for_env(env, DecoupledMPCConfig(high_level=high_level))
    modes = {"unified": "level", "unified-waiter": "specific_force"}
    config = HierarchicalConfig(tray_mode=modes[name], high_level=high_level)  # type: ignore[arg-type]
    return HierarchicalController.for_env(env, config)


def trace(env_id: str, controller: str, goal: float, friction: float, seconds: float,
          plan: PlanConfig) -> dict:  # fmt: skip
    env = gym.make(env_id, goal=goal, cup_friction=friction)
    observation, info = env.reset(seed=0)
    policy = make_policy(controller, env, plan)
    policy.reset(observation, info)
    rows = []
    for n in range(int(round(seconds / env.unwrapped.dt))):
        observation, _, terminated, _, info = env.step(policy(observation))
        rows.append(((n + 1) * env.unwrapped.dt, info["x"], info["xd"],
                     info["cup_friction_use"], info["tray_tilt_deg"]))  # fmt: skip
        if terminated:
            break
    env.close()
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
        "cup_kept": bool(info["cup_on_tray"]),
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
            print(f"| {t[i]:.2f} | {x[i]:.3f} | {xd[i]:.2f} | {a[i]:.2f} | "
                  f"{np.degrees(np.arctan(a[i] / 9.81)):.1f} | {tilt[i]:.1f} | "
                  f"{friction_use[i]:.2f} |")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="wip_gym/PlanarTray-v0")
    parser.add_argument("--goal", type=float, default=2.0)
    parser.add_argument("--cup-friction", type=float, default=0.3)
    parser.add_argument("--duration", type=float, default=8.0)
    parser.add_argument("--controllers", default="decoupled,decoupled-mpc,unified,unified-waiter")
    parser.add_argument("--a-max", type=float, default=None, help="m/s^2 (default 0.5 mu g)")
    parser.add_argument("--q-position", type=float, default=PlanConfig.q_position)
    parser.add_argument("--theta-max", type=float, default=PlanConfig.theta_max)
    parser.add_argument("--trace", default="", help="controllers whose time series to print")
    parser.add_argument("--window", default="0:2", help="START:STOP s of the time series")
    parser.add_argument("--every", type=float, default=0.05, help="s between rows")
    args = parser.parse_args()
    plan = PlanConfig(a_max=args.a_max, q_position=args.q_position, theta_max=args.theta_max)
    header = ("controller", "plan peak a", "roll back cm", "lurch ends s", "lurch: friction (at s)",
              "lurch: tilt deg", "after: friction", "after: tilt deg", "peak xd",
              "cup kept")  # fmt: skip
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for name in args.controllers.split(","):
        r = trace(args.env, name, args.goal, args.cup_friction, args.duration, plan)
        if r["plan_violations"]:
            print(f"plan violations: {r['plan_violations']}")
        print(f"| {name} | {r['plan_peak_a']:.2f} | {r['roll_back_cm']:.1f} | "
              f"{r['lurch_end_s']:.2f} | "
              f"{r['lurch_friction']:.2f} ({r['lurch_friction_at_s']:.2f}) | "
              f"{r['lurch_tilt_deg']:.1f} | {r['rest_friction']:.2f} | {r['rest_tilt_deg']:.1f} | "
              f"{r['peak_speed']:.2f} | {'yes' if r['cup_kept'] else 'no'} |",
              flush=True)  # fmt: skip
        if name in args.trace.split(","):
            start, stop = (float(v) for v in args.window.split(":"))
            print(f"\n{name}:")
            print_series(r["series"], start, stop, args.every)
            print()


if __name__ == "__main__":
    main()
