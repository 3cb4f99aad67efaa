"""The task QP's per-step Python in the closed loop, against a bound: the same control step
with the QP's step cut down to its compiled call.

    python -m benchmarks.speed.guard_bound [--env wip_gym/KrangTray-v0] [--rounds 3]
                                           [--steps 3000]

Each round runs ``unified`` in its closed loop twice from the same reset (seed = the round):
300 steps to settle, then ``--steps`` timed (``policy(obs)`` alone, the collector frozen as
``wip-bench profile`` freezes it), first as the controller is, then with the bound. The unit
(``benchmarks.speed.yardstick``) is timed after each loop.

The bound replaces ``TaskQP.solve`` for the run (on the instance) by what its common case must
do around its one compiled call (``controllers.low_level.compiled_step.rows_and_kernel``): the
observers marked to advance and the rows' weights copied. It skips the rest of that case's
Python: the checks that a user's changes between two steps are seen (the task list, a frame
task's site, a posture task's columns, the row buffers, the call's table, a task another stack
took), the observers' memo in ``robot.cache`` and the copies the solution hands out. It is not a
controller to run (a change between steps would go unseen); it bounds what a compiled control
step with a frozen structure could save there. A step whose unconstrained minimiser is not
feasible goes on to ProxQP through the controller's own path (the observers memoised first, so
they do not advance twice). Both loops give the same actions to the bit (checked).

Printed: per mode the control step's median and mean over the timed steps, in units, each the
median over the rounds, and the difference.
"""

from __future__ import annotations

import argparse
import gc
import time
from typing import Any

import gymnasium as gym
import numpy as np

import wip_gym  # noqa: F401  (registers the envs)
from benchmarks.speed.yardstick import ReferenceStep
from controllers.low_level.compiled_step import rows_and_kernel
from controllers.low_level.task_qp import QPSolution
from controllers.optimizer import jax_setup
from controllers.registry import make_policy

SETTLE_STEPS = 300
MODES = ("as it is", "bound")


def cut_down_solve(policy: Any) -> None:
    """Replace ``policy.qp.solve`` on the instance by the bound (module docstring). The QP's
    compiled stack and table must be made already (after the first steps)."""
    qp = policy.qp
    stack, kernel = qp._stack, qp.kernel
    if stack is None:
        raise RuntimeError("the task QP has no compiled stack yet: step it first")
    table = stack.table
    solve = qp.solve

    def bound(robot: Any, iso: Any, tasks: Any, constraints: Any = ()) -> QPSolution:
        stack.prepare(robot)
        if rows_and_kernel(table.rows):
            k = kernel
            return QPSolution(k.x, k.nu_dot, k.generalized, k.actuators, True, 0)
        stack.memoise_observers(robot)
        return solve(robot, iso, tasks, constraints)

    qp.solve = bound


def timed_loop(env_id: str, seed: int, steps: int, cut_down: bool) -> tuple[np.ndarray, np.ndarray]:
    """One closed loop: the control step's times (ns) and the actions of the timed steps."""
    env = gym.make(env_id, max_episode_steps=-1)
    observation, info = env.reset(seed=seed)
    policy = make_policy("unified", env)
    policy.reset(observation, info)
    for _ in range(SETTLE_STEPS):
        observation, *_ = env.step(policy(observation))
    if cut_down:
        cut_down_solve(policy)
    times = np.zeros(steps)
    actions = np.zeros((steps, env.action_space.shape[0]))
    gc.collect()
    gc.freeze()
    gc.disable()
    try:
        for n in range(steps):
            start = time.perf_counter_ns()
            action = policy(observation)
            times[n] = time.perf_counter_ns() - start
            actions[n] = action
            observation, _, terminated, _, info = env.step(action)
            if terminated:
                raise RuntimeError(f"{env_id}: the episode ended at step {n}: {info}")
    finally:
        gc.enable()
        gc.unfreeze()
        env.close()
    return times, actions


def measure(env_id: str, rounds: int, steps: int) -> dict[str, dict[str, list[float]]]:
    """Per mode, the rounds' control medians and means in units."""
    jax_setup.configure()
    reference = ReferenceStep()
    results: dict[str, dict[str, list[float]]] = {m: {"median": [], "mean": []} for m in MODES}
    for seed in range(rounds):
        actions = []
        for mode in MODES:
            times, taken = timed_loop(env_id, seed, steps, cut_down=mode == "bound")
            unit_ns = float(np.median(reference.burst())) * 1e9
            results[mode]["median"].append(float(np.median(times)) / unit_ns)
            results[mode]["mean"].append(float(np.mean(times)) / unit_ns)
            actions.append(taken)
        if not np.array_equal(actions[0], actions[1]):
            raise AssertionError(f"round {seed}: the bound's actions differ from the controller's")
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="wip_gym/KrangTray-v0")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=3000)
    args = parser.parse_args(argv)
    if args.rounds < 1 or args.steps < 1:
        parser.error("--rounds and --steps must be positive")
    results = measure(args.env, args.rounds, args.steps)
    print(f"unified on {args.env}: control step in units, median over {args.rounds} rounds")
    print("| | median | mean |")
    print("|---|---|---|")
    for mode in MODES:
        median, mean = (float(np.median(results[mode][key])) for key in ("median", "mean"))
        print(f"| {mode} | {median:.2f} | {mean:.2f} |")
    saved = [
        float(np.median(np.subtract(results["as it is"][key], results["bound"][key])))
        for key in ("median", "mean")
    ]
    print(f"| saved by the bound | {saved[0]:.2f} | {saved[1]:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
