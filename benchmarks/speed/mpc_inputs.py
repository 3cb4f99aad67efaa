"""The MPC step's inputs made inside the closed loop: the compiled path against the reference.

    python -m benchmarks.speed.mpc_inputs [--env wip_gym/KrangTray-v0] [--steps 6000] [--seed 0]

One episode of ``unified``; at the middle of every MPC period (after an env step, where the
caches hold what the loop left in them, as at an MPC tick), both ways of making the MPC's packed
inputs from the robot run once, in a random order:

* ``reference``: ``ModelPredictiveController.inputs(index, wipm_state(robot),
  params_from_robot(robot))`` (the path before ``RobotModel.wipm_inputs``);
* ``compiled``: ``ModelPredictiveController.inputs_from(index, robot)`` (the high level's
  path: one compiled call writes the state and ``lambda(q)`` into the packed inputs).

Each call is checked to give the same vector to the bit; each path runs once before the
episode (its compiled calls loaded from numba's cache). Printed: the median and mean of each,
over all calls and over the calls that ran first (the second reads what the first brought into
the caches), in us of the machine it runs on.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from benchmarks.overrides import resolve_run
from benchmarks.speed.profile import make_env
from controllers.optimizer import jax_setup
from controllers.registry import make_policy
from controllers.simplified.wipm import params_from_robot
from controllers.simplified.wipm_problem import wipm_state

PATHS = ("reference", "compiled")


def run(env_id: str, steps: int, seed: int) -> dict[str, Any]:
    """One episode (module docstring): per path, every call's time and whether it ran first,
    in us."""
    if steps < 10:
        raise ValueError(f"steps must be >= 10 (one MPC period), got {steps}")
    spec = resolve_run(env_id, ["unified"], None, overrides={}, ignore_other_controllers=True)
    env = make_env(env_id, spec.env_kwargs)
    policy = make_policy("unified", env, config=spec.configs["unified"])
    obs, info = env.reset(seed=seed)
    policy.reset(obs, info)
    robot, high_level = policy.robot, policy.high_level
    period = high_level.steps_per_mpc
    # each path's compiled calls loaded (the reference's is no longer on the controller's path)
    high_level.mpc.inputs(0, wipm_state(robot), params_from_robot(robot))
    high_level.mpc.inputs_from(0, robot)
    rng = np.random.default_rng(seed)
    times: dict[str, list[float]] = {path: [] for path in PATHS}
    first: dict[str, list[float]] = {path: [] for path in PATHS}
    for k in range(steps):
        obs, *_ = env.step(policy(obs))
        if k % period != period // 2:
            continue
        mpc = high_level.mpc
        hosts = {}
        order = rng.permutation(len(PATHS))
        for position, which in enumerate(order):
            path = PATHS[which]
            start = time.perf_counter()
            if path == "reference":
                hosts[path] = mpc.inputs(k // period, wipm_state(robot), params_from_robot(robot))
            else:
                hosts[path] = mpc.inputs_from(k // period, robot)
            elapsed = (time.perf_counter() - start) * 1e6
            times[path].append(elapsed)
            if position == 0:
                first[path].append(elapsed)
        if not np.array_equal(hosts["reference"], hosts["compiled"]):
            raise AssertionError(f"the two paths' inputs differ at step {k}")
    env.close()
    return {"times_us": times, "first_us": first}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="wip_gym/KrangTray-v0")
    parser.add_argument("--steps", type=int, default=6000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    if args.steps < 10:
        parser.error("--steps must be >= 10")
    jax_setup.configure()
    result = run(args.env, args.steps, args.seed)
    print(f"the MPC's inputs inside the closed loop of unified on {args.env}, us")
    print("| path | calls | median | mean | median when first (calls) |")
    print("|---|---|---|---|---|")
    for path in PATHS:
        values, when_first = result["times_us"][path], result["first_us"][path]
        first = f"{np.median(when_first):.1f}" if when_first else "-"
        print(
            f"| {path} | {len(values)} | {np.median(values):.1f} | {np.mean(values):.1f} | "
            f"{first} ({len(when_first)}) |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
