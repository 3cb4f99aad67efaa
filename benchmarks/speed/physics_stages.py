"""Where a controlled episode's physics goes: ``mj_step`` by MuJoCo's stages, and what other
solver options would cost and change, on states of a ``unified`` episode.

    python -m benchmarks.speed.physics_stages [--env wip_gym/KrangTray-v0] [--states 100]
                                              [--repeats 30]

The states: every 15th step of an episode of ``unified`` after its first 200 steps (the
controller's torques in ``ctrl``, the solver's warm start in ``qacc_warmstart``). At each, the
median over ``--repeats`` of the stages run cumulatively from a restored copy of the state
(``mj_copyData``, whose own median is subtracted), in ``mj_forward``'s order: a stage's figure
is the growth of the cumulative time, so the restore and the stages before it cancel. The
figures are medians over the states, in us and in units (a bare warm ``mj_step`` of Krang-v0,
``benchmarks.speed.yardstick``, taken once per state).

The options: the same states stepped once by a copy of the model with one option changed,
against the model's own step: the median cost in units and the largest difference of the
stepped ``qpos, qvel`` (0 when the option changes no bit of the physics).
"""

from __future__ import annotations

import argparse
import copy
from collections.abc import Callable

import gymnasium as gym
import mujoco
import numpy as np

import wip_gym  # noqa: F401  (registers the envs)
from benchmarks.speed.yardstick import ReferenceStep, median_call_us
from controllers.optimizer import jax_setup
from controllers.registry import make_policy

Stage = Callable[[mujoco.MjModel, mujoco.MjData], None]

#: mj_forward's stages in its order (mj_fwdPosition's parts first), then what mj_step adds
STAGES: tuple[tuple[str, Stage], ...] = (
    ("mj_kinematics", mujoco.mj_kinematics),
    ("mj_comPos", mujoco.mj_comPos),
    ("mj_camlight", mujoco.mj_camlight),
    ("mj_flex", mujoco.mj_flex),
    ("mj_tendon", mujoco.mj_tendon),
    ("mj_makeM", mujoco.mj_makeM),
    ("mj_factorM", mujoco.mj_factorM),
    ("mj_collision", mujoco.mj_collision),
    ("mj_makeConstraint", mujoco.mj_makeConstraint),
    ("mj_island", mujoco.mj_island),  # nothing when the model disables islands
    ("mj_transmission", mujoco.mj_transmission),
    ("mj_projectConstraint", mujoco.mj_projectConstraint),
    ("mj_fwdVelocity", mujoco.mj_fwdVelocity),
    ("mj_fwdActuation", mujoco.mj_fwdActuation),
    ("mj_fwdAcceleration", mujoco.mj_fwdAcceleration),
    ("mj_fwdConstraint", mujoco.mj_fwdConstraint),
)


def _set(field: str, value: int) -> Callable[[mujoco.MjModel], None]:
    def apply(model: mujoco.MjModel) -> None:
        setattr(model.opt, field, value)

    return apply


def _toggle_islands(model: mujoco.MjModel) -> None:
    model.opt.disableflags ^= int(mujoco.mjtDisableBit.mjDSBL_ISLAND)


#: one option changed each (the model's own: implicitfast, dense Jacobians, Newton, islands as
#: the model has them)
OPTIONS: dict[str, Callable[[mujoco.MjModel], None]] = {
    "islands toggled": _toggle_islands,
    "integrator Euler": _set("integrator", int(mujoco.mjtIntegrator.mjINT_EULER)),
    "sparse Jacobians": _set("jacobian", int(mujoco.mjtJacobian.mjJAC_SPARSE)),
    "solver CG": _set("solver", int(mujoco.mjtSolver.mjSOL_CG)),
    "solver PGS": _set("solver", int(mujoco.mjtSolver.mjSOL_PGS)),
}


def controlled_states(
    env_id: str, count: int, warmup: int = 200, spacing: int = 15, seed: int = 0
) -> tuple[mujoco.MjModel, list[mujoco.MjData]]:
    """The env's model and ``count`` states of an episode of ``unified`` (every ``spacing``-th
    step after ``warmup``). ``ValueError`` if the episode ends first."""
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    env = gym.make(env_id, max_episode_steps=-1)
    observation, info = env.reset(seed=seed)
    policy = make_policy("unified", env)
    policy.reset(observation, info)
    model, data = env.unwrapped.model, env.unwrapped.data
    states: list[mujoco.MjData] = []
    step = 0
    while len(states) < count:
        observation, _, terminated, _, info = env.step(policy(observation))
        step += 1
        if terminated:
            raise ValueError(f"{env_id}: the episode ended at step {step}: {info}")
        if step > warmup and step % spacing == 0:
            state = mujoco.MjData(model)
            mujoco.mj_copyData(state, model, data)
            states.append(state)
    return model, states


def stage_costs(
    model: mujoco.MjModel,
    states: list[mujoco.MjData],
    repeats: int,
    reference: ReferenceStep,
) -> dict[str, tuple[float, float]]:
    """Each stage's median growth of the cumulative time over the states, ``(us, units)``;
    also ``mj_forward``, ``mj_step`` and the integration (``mj_step`` minus ``mj_forward``)."""
    work = mujoco.MjData(model)
    rows: dict[str, list[float]] = {name: [] for name, _ in STAGES}
    rows.update({"mj_forward": [], "mj_step": [], "integration": []})
    units: list[float] = []
    for state in states:

        def restore(state: mujoco.MjData = state) -> None:
            mujoco.mj_copyData(work, model, state)

        base = median_call_us(restore, repeats)
        previous = 0.0
        for k, (name, _) in enumerate(STAGES):

            def run(state: mujoco.MjData = state, upto: int = k + 1) -> None:
                mujoco.mj_copyData(work, model, state)
                for _, stage in STAGES[:upto]:
                    stage(model, work)

            cumulative = median_call_us(run, repeats) - base
            rows[name].append(cumulative - previous)
            previous = cumulative

        def forward(state: mujoco.MjData = state) -> None:
            mujoco.mj_copyData(work, model, state)
            mujoco.mj_forward(model, work)

        def step(state: mujoco.MjData = state) -> None:
            mujoco.mj_copyData(work, model, state)
            mujoco.mj_step(model, work)

        rows["mj_forward"].append(median_call_us(forward, repeats) - base)
        rows["mj_step"].append(median_call_us(step, repeats) - base)
        rows["integration"].append(rows["mj_step"][-1] - rows["mj_forward"][-1])
        units.append(1e6 * float(np.median(reference.burst())))
    unit = np.asarray(units)
    return {
        name: (float(np.median(values)), float(np.median(np.asarray(values) / unit)))
        for name, values in rows.items()
    }


def option_costs(
    model: mujoco.MjModel,
    states: list[mujoco.MjData],
    repeats: int,
    reference: ReferenceStep,
) -> dict[str, tuple[float, float, float]]:
    """Per option (and the model's own, ``as built``): the median ``mj_step`` in units over
    the states, the mean solver iterations, and the largest ``|qpos, qvel|`` difference of the
    stepped states from the model's own step."""
    variants = {"as built": model}
    for name, apply in OPTIONS.items():
        variant = copy.copy(model)
        apply(variant)
        variants[name] = variant
    ratios: dict[str, list[float]] = {name: [] for name in variants}
    iterations: dict[str, list[int]] = {name: [] for name in variants}
    stepped: dict[str, list[np.ndarray]] = {name: [] for name in variants}
    for state in states:
        unit = 1e6 * float(np.median(reference.burst()))
        for name, variant in variants.items():
            work = mujoco.MjData(variant)

            def restore(state: mujoco.MjData = state, work: mujoco.MjData = work) -> None:
                mujoco.mj_copyData(work, model, state)

            def step(
                state: mujoco.MjData = state,
                work: mujoco.MjData = work,
                variant: mujoco.MjModel = variant,
            ) -> None:
                mujoco.mj_copyData(work, model, state)
                mujoco.mj_step(variant, work)

            cost = median_call_us(step, repeats) - median_call_us(restore, repeats)
            ratios[name].append(cost / unit)
            step()  # the timing ended on a restore: the stepped state is read after this step
            iterations[name].append(int(work.solver_niter[0]))
            stepped[name].append(np.concatenate([work.qpos, work.qvel]))
    own = np.asarray(stepped["as built"])
    return {
        name: (
            float(np.median(ratios[name])),
            float(np.mean(iterations[name])),
            float(np.max(np.abs(np.asarray(stepped[name]) - own))),
        )
        for name in variants
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="wip_gym/KrangTray-v0")
    parser.add_argument("--states", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args(argv)
    if args.states < 1 or args.repeats < 1:
        parser.error("--states and --repeats must be >= 1")
    jax_setup.configure()
    reference = ReferenceStep()
    model, states = controlled_states(args.env, args.states)
    print(f"{args.env}: {len(states)} states of a controlled episode, {args.repeats} repeats each")
    print("\n| stage | us | units |\n|---|---|---|")
    for name, (us, units) in stage_costs(model, states, args.repeats, reference).items():
        print(f"| {name} | {us:.2f} | {units:.3f} |")
    print("\n| option | mj_step, units | solver iterations | max abs(qpos, qvel) change |")
    print("|---|---|---|---|")
    for name, (units, iters, change) in option_costs(
        model, states, args.repeats, reference
    ).items():
        print(f"| {name} | {units:.3f} | {iters:.2f} | {change:.1e} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
