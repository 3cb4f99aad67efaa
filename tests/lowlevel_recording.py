"""Record the low level's reference data for the speed-change guards.

For each case (env, controller mode) it runs ``steps`` closed-loop control steps from a fixed
seed and stores in ``tests/data/lowlevel_<case>.npz``:

* ``qpos``, ``qvel``, ``actions``: the env's full state after every step and every action;
* at every ``every``-th step, what the task QP saw: the observation (``obs_qpos``,
  ``obs_qvel``), the task references (``theta_ref`` = theta_d, thetad_d, thdd_d; ``spin_ref`` =
  psi_d, psid_d, psidd_d; ``orientation_targets``), the assembled QP (``H``, ``g``, ``C``,
  ``lower``, ``upper``) and ProxQP's solution ``x``.

Run it only on the code whose results are the reference (it was run once, before the low
level's speed changes): ``python -m tests.lowlevel_recording``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import wip_gym  # noqa: F401
from controllers.hierarchical import HierarchicalConfig, HierarchicalController

CASES: dict[str, tuple[str, Any, str]] = {
    "planar": ("wip_gym/PlanarTray-v0", 2.0, "level"),
    "planar_waiter": ("wip_gym/PlanarTray-v0", 2.0, "specific_force"),
    "krang": ("wip_gym/KrangTray-v0", (2.0, 0.0), "level"),
    # no cup: the closed loop is smooth (a resting cup's contacts turn 1e-10 into 1e-3)
    "planar_nocup": ("wip_gym/Planar-v0", 2.0, "level"),
    "krang_nocup": ("wip_gym/Krang-v0", (2.0, 1.0), "level"),
}
SEED = 0
DATA = Path(__file__).resolve().parents[1] / "tests" / "data"


def record(case: str, steps: int, every: int) -> dict[str, np.ndarray]:
    env_id, goal, mode = CASES[case]
    env = gym.make(env_id, goal=goal)
    obs, info = env.reset(seed=SEED)
    policy = HierarchicalController.for_env(
        env, HierarchicalConfig(tray_mode=mode, hand_observer_bandwidth=None)
    )
    policy.reset(obs, info)
    samples: dict[str, list[np.ndarray]] = {
        k: []
        for k in (
            "obs_qpos",
            "obs_qvel",
            "theta_ref",
            "spin_ref",
            "orientation_targets",
            "H",
            "g",
            "C",
            "lower",
            "upper",
            "x",
            "step",
        )
    }
    solve = policy.qp.solve
    state = {"step": 0, "obs": obs}

    def recording_solve(robot, iso, tasks):
        if state["step"] % every:
            return solve(robot, iso, tasks)
        H, g, C, lower, upper = policy.qp.assemble(robot, iso, tasks)
        solution = solve(robot, iso, tasks)
        theta = policy.theta_task
        spin = policy.spin_task
        samples["obs_qpos"].append(state["obs"]["qpos"].copy())
        samples["obs_qvel"].append(state["obs"]["qvel"].copy())
        samples["theta_ref"].append(np.array([theta.theta_d, theta.thetad_d, theta.thdd_d]))
        samples["spin_ref"].append(
            np.zeros(3) if spin is None else np.array([spin.psi_d, spin.psid_d, spin.psidd_d])
        )
        samples["orientation_targets"].append(
            np.array([task.target for task in policy.orientation_tasks])
        )
        for name, value in zip(
            ("H", "g", "C", "lower", "upper"), (H, g, C, lower, upper), strict=True
        ):
            samples[name].append(value.copy())
        samples["x"].append(solution.qdd.copy())
        samples["step"].append(np.array(state["step"]))
        return solution

    policy.qp.solve = recording_solve
    qpos, qvel, actions = [], [], []
    for n in range(steps):
        state["step"], state["obs"] = n, obs
        action = policy(obs)
        obs, _, terminated, _, _ = env.step(action)
        assert not terminated
        actions.append(action.copy())
        qpos.append(env.unwrapped.data.qpos.copy())
        qvel.append(env.unwrapped.data.qvel.copy())
    env.close()
    out = {k: np.array(v) for k, v in samples.items()}
    out.update(
        qpos=np.array(qpos), qvel=np.array(qvel), actions=np.array(actions), seed=np.array(SEED)
    )
    return out


def main() -> None:
    from controllers.optimizer import jax_setup

    jax_setup.configure()  # the solvers' JAX settings, before JAX starts
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--every", type=int, default=10)
    parser.add_argument("--cases", nargs="*", default=list(CASES))
    args = parser.parse_args()
    DATA.mkdir(parents=True, exist_ok=True)
    for case in args.cases:
        data = record(case, args.steps, args.every)
        path = DATA / f"lowlevel_{case}.npz"
        np.savez_compressed(path, **data)
        print(f"{path}: {len(data['x'])} QPs, {len(data['qpos'])} steps")


if __name__ == "__main__":
    main()
