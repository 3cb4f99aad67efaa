"""Fill the on-disk compilation caches once, so that the first real run does not pay for them.

    python -m benchmarks.warm_caches [--env ENV ...] [--steps 20]

The compiled parts of the closed loop are cached on disk after their first use: numba's (the
robot model, the env step, the low level: about a minute to compile on 2 cores, milliseconds to
load; the MPC's generated DDP, ``controllers.optimizer.numba_ddp``: about 20 s planar and 35 s
3-D) and JAX's (the DDP plan, ``controllers.optimizer.jax_setup``). This runs a few
control steps of ``unified`` on each env (default: PlanarTray-v0 and KrangTray-v0, the planar and
3-D problems) and prints the time each took. ``make install`` runs it.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym

import wip_gym  # noqa: F401
from controllers.optimizer import jax_setup
from controllers.registry import make_policy

DEFAULT_ENVS = ("wip_gym/PlanarTray-v0", "wip_gym/KrangTray-v0")


def warm(env_id: str, steps: int) -> float:
    """Seconds to make ``env_id``, reset it, build and reset ``unified`` and run ``steps``."""
    start = time.perf_counter()
    env = gym.make(env_id)
    observation, info = env.reset(seed=0)
    policy = make_policy("unified", env)
    policy.reset(observation, info)
    for _ in range(steps):
        observation, *_ = env.step(policy(observation))
    env.close()
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", action="append", help="env id (repeatable)")
    parser.add_argument("--steps", type=int, default=20)
    args = parser.parse_args(argv)
    jax_setup.configure()
    for env_id in args.env or DEFAULT_ENVS:
        print(f"{env_id}: {warm(env_id, args.steps):.1f} s")


if __name__ == "__main__":
    main()
