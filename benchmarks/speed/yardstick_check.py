"""What the profiler's old timing did to what it measured (docs/performance.md §12).

    python -m benchmarks.speed.yardstick_check [--env wip_gym/KrangTray-v0] [--steps 8000]
                                               [--mpc-steps 600]

One episode of ``unified`` on ``--env``, run in blocks of :data:`BLOCK` control steps that
alternate between two kinds:

* *perturbed* blocks do, after every control step, what ``wip-bench profile`` did before
  docs/performance.md §12: a bare ``mj_step`` on a copy of the env's data (the old floor)
  before ``env.step``, and one reference step of the unit after it;
* *plain* blocks do nothing between the steps but the loop's own work.

Printed: the control step's median and mean in the plain blocks over the perturbed blocks
(paired block by block, the median of the ratios); the unit's reference step sampled once after
every loop step against the same step in warm bursts (``ReferenceStep.burst``, one every
:data:`BLOCK` steps); the old floor against the same states replayed back to back after the
episode (``benchmarks.speed.profile.floor_times``). Then the MPC: ``--mpc-steps`` steps of
``wip-bench solvers``' MPC workload per problem, the reference step sampled once after every
MPC step against warm bursts.
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np

BLOCK = 250
"""Control steps per block (perturbed and plain blocks alternate)."""
MPC_BURST_EVERY = 50
"""MPC steps between two warm bursts of the unit (as ``wip-bench solvers``)."""


def loop_check(env_id: str, steps: int) -> None:
    """The closed loop's blocks (module docstring): print the control step's ratio, the unit
    sampled after every step against warm bursts, the old floor against the replayed one."""
    from benchmarks.speed.profile import STATE, floor_times, make_env  # noqa: PLC0415
    from benchmarks.speed.yardstick import ReferenceStep, burst_due  # noqa: PLC0415
    from controllers.registry import make_policy  # noqa: PLC0415

    env = make_env(env_id, {})
    observation, info = env.reset(seed=0)
    policy = make_policy("unified", env)
    policy.reset(observation, info)
    base = env.unwrapped
    model, data = base.model, base.data
    scratch = mujoco.MjData(model)
    reference = ReferenceStep()
    steps -= steps % (2 * BLOCK)
    control = np.zeros(steps)
    single: list[float] = []
    burst: list[float] = []
    old_floor: list[float] = []
    states = np.zeros((steps // 2, mujoco.mj_stateSize(model, STATE)))
    actions = np.zeros((steps // 2, model.nu))
    for n in range(steps):
        perturbed = (n // BLOCK) % 2 == 0
        start = time.perf_counter()
        action = policy(observation)
        control[n] = time.perf_counter() - start
        if perturbed:
            row = len(old_floor)
            mujoco.mj_getState(model, data, states[row], STATE)
            actions[row] = action
            mujoco.mj_copyData(scratch, model, data)
            scratch.ctrl[:] = action
            start = time.perf_counter()
            mujoco.mj_step(model, scratch, nstep=base.frame_skip)
            old_floor.append(time.perf_counter() - start)
        observation, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            raise RuntimeError(f"the episode ended at step {n}: choose fewer --steps")
        if perturbed:
            single.append(reference.sample())
        if burst_due(n, BLOCK, steps):
            burst += reference.burst()
    env.close()
    replayed = floor_times(model, states, actions, base.frame_skip)
    blocks = control.reshape(-1, BLOCK)
    perturbed_blocks, plain_blocks = blocks[0::2], blocks[1::2]
    median_ratio = np.median(np.median(plain_blocks, 1) / np.median(perturbed_blocks, 1))
    mean_ratio = np.median(plain_blocks.mean(1) / perturbed_blocks.mean(1))
    print(f"{env_id}, unified, {steps} steps in blocks of {BLOCK}:")
    print(
        f"  control step, plain over perturbed blocks: median {median_ratio:.2f}, "
        f"mean {mean_ratio:.2f}"
    )
    print(
        f"  unit: one sample after every loop step {np.median(single) * 1e6:.1f} us, "
        f"warm bursts {np.median(burst) * 1e6:.1f} us "
        f"(ratio {np.median(single) / np.median(burst):.2f})"
    )
    print(
        f"  floor: a copy stepped right after the control step {np.median(old_floor) * 1e6:.1f} "
        f"us, the same states replayed {np.median(replayed) * 1e6:.1f} us (medians; ratio "
        f"{np.median(old_floor) / np.median(replayed):.2f})",
        flush=True,
    )


def mpc_check(steps: int) -> None:
    """``steps`` MPC steps per problem: print the unit sampled after every step against warm
    bursts, and the step in both units."""
    from benchmarks.speed.ddp_bench import GOALS, initial_state, krang_params  # noqa: PLC0415
    from benchmarks.speed.yardstick import ReferenceStep, burst_due  # noqa: PLC0415
    from controllers.high_level.mpc import ModelPredictiveController  # noqa: PLC0415
    from controllers.high_level.planning import plan_to_goal  # noqa: PLC0415

    params, theta0 = krang_params()
    reference = ReferenceStep()
    for problem in ("planar", "3d"):
        goal = np.asarray(GOALS[problem])
        state = initial_state(problem, theta0)
        plan = plan_to_goal(state, params, goal, planar=problem == "planar")
        controller = ModelPredictiveController(plan)
        controller.step(0, plan.states[0], params)  # compiles
        times: list[float] = []
        single: list[float] = []
        burst: list[float] = []
        for i in range(steps):
            index = i % (len(plan.states) - 1)
            start = time.perf_counter()
            controller.step(index, plan.states[index], params)
            times.append(time.perf_counter() - start)
            single.append(reference.sample())
            if burst_due(i, MPC_BURST_EVERY, steps):
                burst += reference.burst()
        step, cold, warm = np.median(times), np.median(single), np.median(burst)
        print(
            f"MPC {problem}: step {step * 1e6:.0f} us; unit sampled after every step "
            f"{cold * 1e6:.1f} us ({step / cold:.1f} units), in warm bursts {warm * 1e6:.1f} us "
            f"({step / warm:.1f} units)",
            flush=True,
        )


def main(argv: list[str] | None = None) -> int:
    from controllers.optimizer import jax_setup  # noqa: PLC0415

    jax_setup.configure()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="wip_gym/KrangTray-v0")
    parser.add_argument("--steps", type=int, default=8000, help="control steps of the episode")
    parser.add_argument("--mpc-steps", type=int, default=600, help="MPC steps per problem")
    args = parser.parse_args(argv)
    if args.steps < 2 * BLOCK or args.mpc_steps < 50:
        parser.error(f"--steps must be >= {2 * BLOCK} and --mpc-steps >= 50")
    import wip_gym  # noqa: F401, PLC0415  (registers the envs)

    loop_check(args.env, args.steps)
    mpc_check(args.mpc_steps)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
