"""The env's own work per step, beyond its physics, in units (the issue's "env's own work").

    python -m benchmarks.speed.env_own_work [--states 40] [--repeats 100]

For every registered robot env: ``--states`` states of an episode under zero torques (5 steps
apart); at each, the median over ``--repeats`` of ``env.step`` and of a bare ``mj_step`` of the
env's model, each from that state restored by ``mj_copyData`` (the same restore in both, so it
cancels); the env's own work is their difference, its median over the states is reported in
units of a bare ``mj_step`` of Krang-v0 timed in the same process
(``benchmarks.speed.yardstick``). Unlike ``wip-bench profile``'s ``env_overhead`` (``env.step``
minus its own ``mj_step`` inside the closed loop, where the controller's work evicts the env's
code and data from the caches), it measures the env alone, warm.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import mujoco
import numpy as np

import wip_gym  # noqa: F401  (registers the envs)
from benchmarks.speed.yardstick import median_call_us, reference_step_us

ENVS = ("wip_gym/KrangTray-v0", "wip_gym/PlanarTray-v0", "wip_gym/Krang-v0", "wip_gym/Planar-v0")


def own_work_us(env_id: str, states: int = 40, repeats: int = 100) -> float:
    """The median over ``states`` states of ``env.step`` minus a bare ``mj_step`` (us)."""
    if states < 1 or repeats < 1:
        raise ValueError(f"states and repeats must be >= 1, got {states}, {repeats}")
    env = gym.make(env_id).unwrapped
    env.reset(seed=0)
    m, d = env.model, env.data
    action = np.zeros(m.nu)
    saved = []
    for _ in range(states):
        for _ in range(5):
            env.step(action)
        snapshot = mujoco.MjData(m)
        mujoco.mj_copyData(snapshot, m, d)
        saved.append(snapshot)
    differences = []
    for snapshot in saved:

        def full(snapshot: mujoco.MjData = snapshot) -> None:
            mujoco.mj_copyData(d, m, snapshot)
            env.step(action)

        def bare(snapshot: mujoco.MjData = snapshot) -> None:
            mujoco.mj_copyData(d, m, snapshot)
            mujoco.mj_step(m, d)

        differences.append(median_call_us(full, repeats) - median_call_us(bare, repeats))
    env.close()
    return float(np.median(differences))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--states", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=100)
    args = parser.parse_args(argv)
    if args.states < 1 or args.repeats < 1:
        parser.error("--states and --repeats must be >= 1")
    figures = {env_id: own_work_us(env_id, args.states, args.repeats) for env_id in ENVS}
    unit = reference_step_us()
    print(f"env's own work per step, units (unit {unit:.1f} us, target <= 1):")
    for env_id, us in figures.items():
        print(f"  {env_id:24s} {us / unit:5.2f}  ({us:.1f} us)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
