"""How often the task QP needs ProxQP, scenario by scenario: the share of control steps whose
unconstrained minimiser broke a constraint (the QP kernel's shortcut, docs/performance.md §7,
takes every other step).

    python -m benchmarks.speed.qp_paths [--seeds 3] [--duration 10]
                                        [--controllers unified,unified-waiter]

For each tray env, scenario and controller, ``--seeds`` episodes (seeds 0, 1, ...) through the
one rollout (``benchmarks.rollout``), and from the policy's per-step ``qp_iterations`` (0 on a
shortcut step) the steps ProxQP solved. Printed per row: the mean share of ProxQP steps over
the seeds, the largest, the largest count in one episode, and how many episodes ended early (a
fall or a lost cup ends an episode: the share is of the steps it took). The scenarios are the
default drive, the paper's configuration (``--preset paper``), a 150 N push against the
drive for 0.2 s at 2.5 s, a 3 kg payload put in the hand at 2.5 s, the free tray, and masses
randomised by 5 % (the sweep's ``env.mass_randomization``).
"""

from __future__ import annotations

import argparse
from typing import Any

import gymnasium as gym
import numpy as np

from benchmarks.overrides import resolve_run
from benchmarks.rollout import rollout
from controllers.optimizer import jax_setup

ENVS = ("wip_gym/PlanarTray-v0", "wip_gym/KrangTray-v0")
#: (name, preset, env overrides)
SCENARIOS: tuple[tuple[str, str | None, dict[str, Any]], ...] = (
    ("default", None, {}),
    ("paper", "paper", {}),
    (
        "push -150 N",
        None,
        {"env.push_force": -150.0, "env.push_time": 2.5, "env.push_duration": 0.2},
    ),
    ("payload 3 kg", None, {"env.payload_mass": 3.0, "env.payload_time": 2.5}),
    ("free tray", None, {"env.tray_attachment": "free"}),
    ("masses +-5 %", None, {"env.mass_randomization": 0.05}),
)


def proxqp_steps(
    env_id: str,
    controller: str,
    preset: str | None,
    overrides: dict[str, Any],
    seed: int,
    duration: float,
) -> tuple[int, int]:
    """``(steps solved by ProxQP, steps)`` of one episode."""
    spec = resolve_run(env_id, [controller], preset, overrides=overrides)
    episode = rollout(env_id, spec.env_kwargs, controller, spec.configs[controller], seed, duration)
    iterations = np.asarray(episode.policy.diagnostics["qp_iterations"])
    return int(np.sum(iterations > 0)), int(episode.metrics["steps"])


def main() -> None:
    jax_setup.configure()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--controllers", default="unified,unified-waiter")
    args = parser.parse_args()
    if args.seeds < 1 or args.duration <= 0:
        parser.error("--seeds must be at least 1 and --duration positive")
    controllers = [name.strip() for name in args.controllers.split(",") if name.strip()]
    print(f"{args.seeds} seeds, {args.duration} s episodes")
    print(
        "| env | scenario | controller | ProxQP steps, mean share | largest share | largest "
        "count | episodes ended early |"
    )
    print("|---|---|---|---|---|---|---|")
    for env_id in ENVS:
        probe = gym.make(env_id)
        full = round(args.duration / probe.unwrapped.dt)  # the steps of an episode run through
        probe.close()
        for name, preset, overrides in SCENARIOS:
            for controller in controllers:
                runs = [
                    proxqp_steps(env_id, controller, preset, overrides, seed, args.duration)
                    for seed in range(args.seeds)
                ]
                shares = [solved / steps for solved, steps in runs]
                early = sum(steps < full for _, steps in runs)
                print(
                    f"| {env_id.split('/')[-1]} | {name} | {controller} "
                    f"| {100 * np.mean(shares):.2f} % | {100 * max(shares):.2f} % "
                    f"| {max(solved for solved, _ in runs)} | {early} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
