"""The native vector env's steps per second against the single env's, and against Gymnasium's
``SyncVectorEnv`` and ``AsyncVectorEnv`` in the same run (docs/vector.md §3).

    taskset -c 0 python -m benchmarks.speed.vector_env          # one core
    python -m benchmarks.speed.vector_env                       # every core it may use

For each env and action (``zero``: zero torques, the robot falls in about 300 steps; ``random``:
uniform torques over the whole action space, a fall every few tens of steps), every contender
runs in turn for ``--block`` seconds, ``--rounds`` times (the first round is a warm-up and is
dropped):

- ``single``: ``gymnasium.make(id)`` stepped and reset when it ends, as a user's loop does;
- ``native``: ``gymnasium.make_vec(id, num_envs=N)``, the env's own vector env (one thread);
  ``threads``: the same with a thread per core this process may use (``num_threads``);
- ``sync``, ``async``: ``make_vec(..., vectorization_mode="sync" | "async")``.

A vector env's rate is ``N`` times its vector steps per second (its sub-envs' steps); each
contender's ratio in a round is its rate over the single env's in the same round, and the
figure is the median of the rounds' ratios (the machine's load drifts between rounds; a round
is short). The actions are drawn before the clock starts (one table, replayed in turn).

``--split`` measures instead where a sub-env's step goes (this thread's CPU time, one thread,
the median of rounds taken in turn): the single env's step and the native vector env's per
sub-env, and the part of the latter in its compiled steps (``wip_gym.vector.compiled``: the
physics, the measures, the reward and the ends, holding no GIL). The bounds it prints: one
thread, single over native; two threads, single over the larger of the GIL's part and half the
step (a GIL-bound part can overlap only the other thread's compiled part).

Two clocks: ``wall`` (``time.perf_counter``, the figure) and ``cpu`` (``time.process_time``:
this process's CPU time, its threads summed, the ``async`` workers' not counted, so that
contender gets none). On one core shared with other processes the wall clock counts their
turns too; the CPU ratio of ``native`` and ``sync`` is then the steadier estimate of the same
figure. With more than one core the CPU ratio of ``threads`` is its work, not its
speed.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import wip_gym  # noqa: F401  (registers the envs)
from wip_gym.vector import compiled
from wip_gym.vector.env import available_cores

ENVS = ("wip_gym/WIP-v0", "wip_gym/Planar-v0", "wip_gym/PlanarTray-v0", "wip_gym/KrangTray-v0")
CONTENDERS = ("single", "native", "threads", "sync", "async")
ACTIONS = ("zero", "random")
TABLE_STEPS = 512  # rows of the action table, replayed in turn


def action_table(space: gym.spaces.Box, kind: str, n: int, seed: int = 0) -> np.ndarray:
    """``(TABLE_STEPS, n, nu)`` actions: zeros, or uniform over the space's bounds."""
    shape = (TABLE_STEPS, n, *space.shape)
    if kind == "zero":
        return np.zeros(shape)
    if kind == "random":
        low, high = space.low.astype(np.float64), space.high.astype(np.float64)
        return np.random.default_rng(seed).uniform(low, high, shape)
    raise ValueError(f"action must be one of {ACTIONS}, got {kind!r}")


class Single:
    """The single env in a user's loop: step, reset when the episode ends."""

    def __init__(self, env_id: str, actions: np.ndarray) -> None:
        self.env = gym.make(env_id)
        self.env.reset(seed=0)
        self.actions = actions[:, 0]
        self.k = 0
        self.width = 1

    def step(self) -> None:
        self.k = (self.k + 1) % TABLE_STEPS
        _, _, terminated, truncated, _ = self.env.step(self.actions[self.k])
        if terminated or truncated:
            self.env.reset()

    def close(self) -> None:
        self.env.close()


class Vector:
    """A vector env (autoresetting itself)."""

    def __init__(self, env: Any, actions: np.ndarray) -> None:
        self.env = env
        self.env.reset(seed=0)
        self.actions = actions
        self.k = 0
        self.width = env.num_envs

    def step(self) -> None:
        self.k = (self.k + 1) % TABLE_STEPS
        self.env.step(self.actions[self.k])

    def close(self) -> None:
        self.env.close()


def make_contender(name: str, env_id: str, n: int, actions: np.ndarray) -> Single | Vector:
    if name == "single":
        return Single(env_id, actions)
    if name == "threads":
        threads = min(available_cores(), n)
        return Vector(gym.make_vec(env_id, num_envs=n, num_threads=threads), actions)
    mode = {"native": None, "sync": "sync", "async": "async"}[name]
    return Vector(gym.make_vec(env_id, num_envs=n, vectorization_mode=mode), actions)


def steps_per_second(step: Callable[[], None], width: int, block: float) -> tuple[float, float]:
    """Sub-env steps per second over about ``block`` seconds of ``step``: by the wall clock and
    by this process's CPU time."""
    calls = 0
    start, cpu_start = time.perf_counter(), time.process_time()
    end = start + block
    now = start
    while now < end:
        for _ in range(8):
            step()
        calls += 8
        now = time.perf_counter()
    cpu = max(time.process_time() - cpu_start, 1e-9)
    return calls * width / (now - start), calls * width / cpu


def measure(
    env_id: str,
    action: str,
    n: int,
    rounds: int,
    block: float,
    contenders: tuple[str, ...] = CONTENDERS,
) -> dict[str, Any]:
    """One env and action: every contender's rate per round and its median ratio to single."""
    probe = gym.make(env_id)
    actions = action_table(probe.action_space, action, n)
    probe.close()
    made = {name: make_contender(name, env_id, n, actions) for name in ("single", *contenders)}
    rates: dict[str, dict[str, list[float]]] = {
        clock: {name: [] for name in made} for clock in ("wall", "cpu")
    }
    try:
        for _ in range(rounds):
            for name, contender in made.items():
                wall, cpu = steps_per_second(contender.step, contender.width, block)
                rates["wall"][name].append(wall)
                rates["cpu"][name].append(cpu)
    finally:
        for contender in made.values():
            contender.close()
    result: dict[str, Any] = {"env": env_id, "action": action, "num_envs": n}
    for clock, by_name in rates.items():
        kept = {name: values[1:] for name, values in by_name.items()}  # round 0 warms up
        result[clock] = {
            "single_steps_per_s": statistics.median(kept["single"]),
            "ratio_to_single": {
                name: statistics.median(v / s for v, s in zip(values, kept["single"], strict=True))
                for name, values in kept.items()
                if name != "single" and not (clock == "cpu" and name == "async")
            },
            "steps_per_s": kept,
        }
    return result


def gil_split(env_id: str, n: int, steps: int = 100, rounds: int = 7) -> dict[str, float]:
    """Microseconds of this thread's CPU per sub-env step (zero torques): ``single``,
    ``native`` (one thread) and ``native_compiled`` (its compiled steps,
    ``wip_gym.vector.compiled.advance``, which hold no GIL), with the bounds of the module's
    docstring. In turn, ``rounds`` times (the first warms up): ``steps`` vector steps, then
    ``steps * n`` single-env steps; each figure is the median of the rounds'."""
    clock = time.thread_time
    inside = [0.0]
    advance = compiled.advance

    def timed_advance(*args: Any) -> int:
        start = clock()
        rejected = advance(*args)
        inside[0] += clock() - start
        return int(rejected)

    vec = gym.make_vec(env_id, num_envs=n)
    single = gym.make(env_id)
    measured: dict[str, list[float]] = {"single": [], "native": [], "compiled": []}
    try:
        vec.reset(seed=0)
        single.reset(seed=0)
        zeros = np.zeros(vec.action_space.shape)
        compiled.advance = timed_advance  # the vector env calls it through the module
        try:
            for _ in range(rounds):
                inside[0] = 0.0
                start = clock()
                for _ in range(steps):
                    vec.step(zeros)
                measured["native"].append((clock() - start) / (steps * n) * 1e6)
                measured["compiled"].append(inside[0] / (steps * n) * 1e6)
                start = clock()
                for _ in range(steps * n):
                    _, _, terminated, truncated, _ = single.step(zeros[0])
                    if terminated or truncated:
                        single.reset()
                measured["single"].append((clock() - start) / (steps * n) * 1e6)
        finally:
            compiled.advance = advance
    finally:
        vec.close()
        single.close()
    alone, native, nogil = (statistics.median(measured[k][1:]) for k in measured)
    held = native - nogil
    return {
        "single_us": alone,
        "native_us": native,
        "native_compiled_us": nogil,
        "one_thread_bound": alone / native,
        "two_thread_bound": alone / max(held, native / 2),
    }


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", nargs="+", default=list(ENVS))
    parser.add_argument("--action", nargs="+", default=list(ACTIONS), choices=ACTIONS)
    parser.add_argument("--num-envs", type=int, default=8)
    parser.add_argument("--rounds", type=int, default=7, help="the first is a warm-up")
    parser.add_argument("--block", type=float, default=0.5, help="seconds per contender")
    parser.add_argument(
        "--contenders",
        nargs="+",
        default=["native", "sync", "async"],
        choices=CONTENDERS[1:],
        help="besides single (threads: the native env on a thread per core)",
    )
    parser.add_argument("--split", action="store_true", help="where a sub-env's step goes")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    if args.split:
        splits = []
        for env_id in args.env:
            split = {"env": env_id, **gil_split(env_id, args.num_envs)}
            splits.append(split)
            print(
                f"{env_id:<24}single {split['single_us']:5.1f} us  native {split['native_us']:5.1f}"
                f" us (compiled {split['native_compiled_us']:5.1f} us)  bounds: one thread "
                f"{split['one_thread_bound']:.2f}, two {split['two_thread_bound']:.2f}",
                flush=True,
            )
        if args.json:
            args.json.write_text(json.dumps(splits, indent=2) + "\n")
        return splits
    if args.rounds < 2 or args.block <= 0 or args.num_envs < 1:
        parser.error("--rounds must be >= 2, --block > 0, --num-envs >= 1")
    cores = available_cores()
    print(
        f"{cores} core(s); N = {args.num_envs}; ratio = N x vector steps/s over single steps/s, "
        "by the wall clock (by CPU time)"
    )
    results = []
    for env_id in args.env:
        for action in args.action:
            result = measure(
                env_id, action, args.num_envs, args.rounds, args.block, tuple(args.contenders)
            )
            result["cores"] = cores
            results.append(result)
            wall, cpu = result["wall"], result["cpu"]
            ratios = "  ".join(
                f"{k} {v:.2f}"
                + (f" ({cpu['ratio_to_single'][k]:.2f})" if k in cpu["ratio_to_single"] else "")
                for k, v in wall["ratio_to_single"].items()
            )
            print(
                f"{env_id:<24}{action:<8}single {wall['single_steps_per_s']:7.0f}/s  {ratios}",
                flush=True,
            )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2) + "\n")
    return results


if __name__ == "__main__":
    main()
