"""Record the low level's reference data for the guards of ``tests/test_lowlevel_recorded.py``.

For each case (env, controller mode) it runs ``steps`` closed-loop control steps of the
controller in its default configuration (:func:`config`: the hand tasks' disturbance observer
on) from a fixed seed and stores in ``tests/data/lowlevel_<case>.npz``:

* ``qpos``, ``qvel``, ``actions``: the env's full state after every step and every action;
* at every ``every``-th step, what the task QP saw: the observation (``obs_qpos``,
  ``obs_qvel``), the task references (``theta_ref`` = theta_d, thetad_d, thdd_d; ``spin_ref`` =
  psi_d, psid_d, psidd_d; ``orientation_targets``), the state each disturbance observer brought
  into the step (``observer_memory``: every observer's ``memory``, in the order of
  :func:`observers`, flattened and concatenated), the assembled QP (``H``, ``g``, ``C``,
  ``lower``, ``upper``) and the solution ``x``.

The observer is deterministic given its inputs: its whole state is its ``memory`` (the
estimate, the last task velocity, the last command and whether a last step exists), advanced
once per robot state from that state's task velocity and the task's own reference by fixed
arithmetic, with no clock and no randomness. So the recorded QP at a sample is a function of
the recorded observation, references and observer state, and the closed loop from a fixed seed
is a function of the seed.

Run it only on the code whose results are the reference: ``python -m tests.lowlevel_recording``.
The guards had held the code to data recorded with the observer off before the low level's
speed changes; the code that recorded these data still met them (the commit before these data
in git history has the guard and the data of that configuration).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import wip_gym  # noqa: F401
from controllers.hierarchical import HierarchicalConfig, HierarchicalController
from controllers.low_level.disturbance_tasks import DisturbanceRejectingTask

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


def config(mode: str) -> HierarchicalConfig:
    """The controller's configuration for a case: the default one in tray mode ``mode``."""
    return HierarchicalConfig(tray_mode=mode)


def observers(policy: HierarchicalController) -> list[DisturbanceRejectingTask]:
    """The controller's disturbance observers, in the order of its tasks."""
    return [task for task in policy.tasks if isinstance(task, DisturbanceRejectingTask)]


def observer_state(policy: HierarchicalController) -> np.ndarray:
    """Every observer's ``memory``, flattened and concatenated (:func:`observers`' order)."""
    return np.concatenate([task.memory.ravel() for task in observers(policy)])


def restore_observer_state(policy: HierarchicalController, state: np.ndarray) -> None:
    """Write ``state`` (as :func:`observer_state` gives it) into the observers' ``memory``, in
    place (a compiled task stack may hold that array)."""
    offset = 0
    for task in observers(policy):
        size = task.memory.size
        task.memory[...] = state[offset : offset + size].reshape(task.memory.shape)
        offset += size
    if offset != len(state):
        raise ValueError(f"an observer state of {offset} values expected, got {len(state)}")


def record(case: str, steps: int, every: int) -> dict[str, np.ndarray]:
    env_id, goal, mode = CASES[case]
    env = gym.make(env_id, goal=goal)
    obs, info = env.reset(seed=SEED)
    policy = HierarchicalController.for_env(env, config(mode))
    policy.reset(obs, info)
    if not observers(policy):
        raise RuntimeError(f"{case}: the default configuration has no disturbance observer")
    samples: dict[str, list[np.ndarray]] = {
        k: []
        for k in (
            "obs_qpos",
            "obs_qvel",
            "theta_ref",
            "spin_ref",
            "orientation_targets",
            "observer_memory",
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
        # the state the observers bring into this step: none has advanced at it yet
        if any(task.cache_key in robot.cache for task in observers(policy)):
            raise RuntimeError("an observer advanced before the step's QP")
        samples["observer_memory"].append(observer_state(policy))
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
