"""What one full pass of the cyclic garbage collector costs in a process that runs a
closed-loop episode, with and without the setup's objects frozen (``benchmarks.heap.
setup_frozen``, which ``wip-bench`` runs its episode loops under).

    python -m benchmarks.speed.gc_pauses [--env wip_gym/KrangTray-v0] [--controller unified]
                                         [--repeats 7]

The collector passes over its oldest generation, every object it tracks, now and then: when
the middle generation has been passed over ten times since and enough objects have reached the
oldest one. When that falls inside an episode's loop depends on everything the process
allocated before, so a change anywhere moves it in or out of a timed episode. This script
makes the heap of a ``wip-bench profile`` process (its CLI module imported, the env made, the
policy reset: its plan and compiled code loaded), then times ``gc.collect()`` (a full pass)
``--repeats`` times plainly and as many times inside ``setup_frozen``, alternating, and prints
the objects the collector tracks and each kind's median and largest pause.
"""

from __future__ import annotations

import argparse
import gc
import time
from contextlib import nullcontext

import gymnasium as gym
import numpy as np

import benchmarks.cli  # noqa: F401  (the heap of a wip-bench process)
from benchmarks.heap import setup_frozen
from controllers.optimizer import jax_setup
from controllers.registry import make_policy


def full_pass_s(frozen: bool) -> float:
    """The time of one ``gc.collect()``, inside :func:`setup_frozen` if ``frozen``."""
    with setup_frozen() if frozen else nullcontext():
        start = time.perf_counter()
        gc.collect()
        return time.perf_counter() - start


def main() -> None:
    jax_setup.configure()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="wip_gym/KrangTray-v0")
    parser.add_argument("--controller", default="unified")
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error("--repeats must be at least 1")
    env = gym.make(args.env, max_episode_steps=-1)
    observation, info = env.reset(seed=0)
    policy = make_policy(args.controller, env)
    policy.reset(observation, info)
    times: dict[bool, list[float]] = {False: [], True: []}
    for r in range(args.repeats):
        for frozen in (False, True) if r % 2 == 0 else (True, False):
            times[frozen].append(full_pass_s(frozen))
    env.close()
    print(f"{args.env} with {args.controller}: {len(gc.get_objects())} objects tracked")
    print("| full pass | median, ms | largest, ms |")
    print("|---|---|---|")
    for frozen, label in ((False, "plain"), (True, "setup frozen")):
        values = np.array(times[frozen]) * 1e3
        print(f"| {label} | {np.median(values):.2f} | {values.max():.2f} |")


if __name__ == "__main__":
    main()
