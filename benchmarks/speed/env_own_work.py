"""The env's own work per step, beyond its physics, in units (the issue's "env's own work").

    python -m benchmarks.speed.env_own_work [--states 40] [--repeats 100]

For every registered robot env: ``--states`` states of an episode under zero torques (5 steps
apart); at each, the median over ``--repeats`` of ``env.step`` and of a bare ``mj_step`` of the
env's model, each from that state restored by ``mj_copyData`` (the same restore in both, so it
cancels), and a warm burst of the unit (a bare ``mj_step`` of Krang-v0,
``benchmarks.speed.yardstick``) right after: the state's own work is the difference of the
two medians over the burst's median, and the env's figure is the median over the states. (The
unit beside each state, not once at the end: this machine's speed drifts by 1.5 times within
a minute.) Unlike ``wip-bench profile``'s ``env_overhead`` (``env.step`` minus its own
``mj_step`` inside the closed loop, where the controller's work evicts the env's code and data
from the caches), it measures the env alone, warm.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import mujoco
import numpy as np

import wip_gym  # noqa: F401  (registers the envs)
from benchmarks.speed.yardstick import ReferenceStep, median_call_us

ENVS = ("wip_gym/KrangTray-v0", "wip_gym/PlanarTray-v0", "wip_gym/Krang-v0", "wip_gym/Planar-v0")


def own_work(
    env_id: str, states: int = 40, repeats: int = 100, reference: ReferenceStep | None = None
) -> tuple[float, float]:
    """The env's own work ``(units, us)``: the medians over ``states`` states of ``env.step``
    minus a bare ``mj_step``, in units of the burst of ``reference`` taken at that state, and
    in microseconds."""
    if states < 1 or repeats < 1:
        raise ValueError(f"states and repeats must be >= 1, got {states}, {repeats}")
    reference = reference or ReferenceStep()
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
    differences, units = [], []
    for snapshot in saved:

        def full(snapshot: mujoco.MjData = snapshot) -> None:
            mujoco.mj_copyData(d, m, snapshot)
            env.step(action)

        def bare(snapshot: mujoco.MjData = snapshot) -> None:
            mujoco.mj_copyData(d, m, snapshot)
            mujoco.mj_step(m, d)

        differences.append(median_call_us(full, repeats) - median_call_us(bare, repeats))
        units.append(1e6 * float(np.median(reference.burst())))
    env.close()
    ratios = np.asarray(differences) / np.asarray(units)
    return float(np.median(ratios)), float(np.median(differences))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--states", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=100)
    args = parser.parse_args(argv)
    if args.states < 1 or args.repeats < 1:
        parser.error("--states and --repeats must be >= 1")
    reference = ReferenceStep()
    figures = {env_id: own_work(env_id, args.states, args.repeats, reference) for env_id in ENVS}
    print("env's own work per step, units (target <= 1), and in us:")
    for env_id, (units, us) in figures.items():
        print(f"  {env_id:24s} {units:5.2f}  ({us:.1f} us)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
