"""What the closed loop's other work costs the low level: its core timed alone, and right
after each kind of work the loop does between two control steps.

    python -m benchmarks.speed.loop_eviction [--env wip_gym/KrangTray-v0] [--rounds 7]
                                             [--calls 400]

The core is the unified controller's low level at one state of a ``unified`` episode (after
600 steps): the robot model's update and the task QP's one compiled call (rows, ``H``, ``g``,
the unconstrained minimiser; ``controllers.low_level.compiled_step``), without the high level
and the Python around them. It is timed ``--calls`` times in a row after each of:

- nothing (the core warm: its code and data in the caches);
- a bare ``mj_step`` of the env's model on a data of its own (MuJoCo's code and the model's
  arrays, not the controller's data);
- the env's step (``env.step`` from the saved state: the physics and the env's measures);
- summing 64 KB and 2 MB arrays (evicting the first-level and the second-level data caches);
- some Python (``json`` and ``sorted``: the interpreter's code, little data);
- the env's step and the 2 MB sum.

The figure per case is the median over ``--rounds`` rounds (the cases alternate within a round)
of the median of its calls, in us, and the difference from the core alone.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import gymnasium as gym
import mujoco
import numpy as np

import wip_gym  # noqa: F401  (registers the envs)
from benchmarks.speed.yardstick import ReferenceStep
from controllers.optimizer import jax_setup
from controllers.registry import make_policy

WARMUP_STEPS = 600


def _python_work() -> None:
    text = json.dumps({"a": [1, 2, 3], "b": {"c": "d"}})
    json.loads(text)
    sorted(str(i) for i in range(30))


def cases(env_id: str) -> tuple[Callable[[], None], dict[str, Callable[[], object] | None]]:
    """The core and the work to run before it, by name (None: nothing)."""
    env = gym.make(env_id, max_episode_steps=-1)
    observation, info = env.reset(seed=0)
    policy = make_policy("unified", env)
    policy.reset(observation, info)
    action = np.zeros(env.action_space.shape)
    for step in range(WARMUP_STEPS):
        action = policy(observation)
        observation, _, terminated, _, info = env.step(action)
        if terminated:
            raise ValueError(f"{env_id}: the episode ended at step {step}: {info}")
    base = env.unwrapped
    model, data = base.model, base.data
    saved, other = mujoco.MjData(model), mujoco.MjData(model)
    mujoco.mj_copyData(saved, model, data)
    mujoco.mj_copyData(other, model, data)
    robot, qp, tasks = policy.robot, policy.qp, policy.tasks  # type: ignore[attr-defined]
    qpos, qvel = observation["qpos"], observation["qvel"]
    small, large = np.ones(8 * 1024), np.ones(256 * 1024)  # 64 KB, 2 MB

    def core() -> None:
        robot.update(qpos, qvel)
        qp._run_kernel(robot, None, tasks)
        if not qp.compiled:
            raise RuntimeError("the task QP did not take its one-call path")

    def bare_step() -> None:
        mujoco.mj_copyData(other, model, saved)
        mujoco.mj_step(model, other)

    def env_step() -> None:
        mujoco.mj_copyData(data, model, saved)
        base.step(action)

    def env_step_and_sweep() -> None:
        env_step()
        large.sum()

    return core, {
        "alone": None,
        "bare mj_step of the env's model": bare_step,
        "env.step": env_step,
        "sum over 64 KB": small.sum,
        "sum over 2 MB": large.sum,
        "Python (json, sorted)": _python_work,
        "env.step, then sum over 2 MB": env_step_and_sweep,
    }


def measure(
    core: Callable[[], None],
    before: dict[str, Callable[[], object] | None],
    rounds: int,
    calls: int,
) -> dict[str, list[float]]:
    """Per case, each round's median core time (us)."""
    if rounds < 1 or calls < 1:
        raise ValueError(f"rounds and calls must be >= 1, got {rounds}, {calls}")
    figures: dict[str, list[float]] = {name: [] for name in before}
    times = np.empty(calls)
    for _ in range(rounds):
        for name, work in before.items():
            for i in range(calls):
                if work is not None:
                    work()
                start = time.perf_counter()
                core()
                times[i] = time.perf_counter() - start
            figures[name].append(float(np.median(times) * 1e6))
    return figures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="wip_gym/KrangTray-v0")
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--calls", type=int, default=400)
    args = parser.parse_args(argv)
    if args.rounds < 1 or args.calls < 1:
        parser.error("--rounds and --calls must be >= 1")
    jax_setup.configure()
    reference = ReferenceStep()
    core, before = cases(args.env)
    figures = measure(core, before, args.rounds, args.calls)
    unit = 1e6 * float(np.median(reference.burst(100)))
    alone = float(np.median(figures["alone"]))
    print(f"{args.env}: the low level's core, {args.rounds} rounds of {args.calls} calls")
    print(f"unit (bare warm mj_step of Krang-v0): {unit:.2f} us\n")
    print("| before each call | core, us: median [min, max] of rounds | minus alone, us |")
    print("|---|---|---|")
    for name, values in figures.items():
        median = float(np.median(values))
        print(
            f"| {name} | {median:.2f} [{min(values):.2f}, {max(values):.2f}] "
            f"| {median - alone:+.2f} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
