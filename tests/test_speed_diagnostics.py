"""The two speed diagnostics that take MuJoCo's step apart and the loop's eviction cost:
what they time is what they say (no bounds on times: they depend on the machine).

- ``benchmarks.speed.physics_stages``: its stages, run in order, are ``mj_forward`` to the bit
  (so the per-stage figures add up the real forward pass, nothing left out or run twice), and
  its option table compares every option against the model's own step.
- ``benchmarks.speed.loop_eviction``: its core is the one-call low level, and each case's work
  runs once before every timed call.
- ``benchmarks.speed.guard_bound``: its bound gives the controller's actions to the bit."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from benchmarks.speed import guard_bound, loop_eviction, physics_stages
from benchmarks.speed.yardstick import ReferenceStep


@pytest.fixture(scope="module")
def planar_states() -> tuple[mujoco.MjModel, list[mujoco.MjData]]:
    return physics_stages.controlled_states("wip_gym/PlanarTray-v0", 3, warmup=20, spacing=5)


def test_the_stages_in_order_are_mj_forward_to_the_bit(planar_states) -> None:
    model, states = planar_states
    assert min(state.ncon for state in states) > 0  # contacts: the constraint stages work
    for state in states:
        by_stages, forward = mujoco.MjData(model), mujoco.MjData(model)
        mujoco.mj_copyData(by_stages, model, state)
        mujoco.mj_copyData(forward, model, state)
        for _, stage in physics_stages.STAGES:
            stage(model, by_stages)
        mujoco.mj_forward(model, forward)
        for name in ("qacc", "qfrc_constraint", "qfrc_bias", "actuator_force", "xpos", "cvel"):
            np.testing.assert_array_equal(getattr(by_stages, name), getattr(forward, name), name)
        np.testing.assert_array_equal(by_stages.efc_force, forward.efc_force)
        # the constraint islands too: mj_forward solves by them when the model has them
        assert by_stages.nisland == forward.nisland
        for name in ("dof_island", "efc_island", "island_nv", "island_nefc", "map_dof2idof"):
            np.testing.assert_array_equal(getattr(by_stages, name), getattr(forward, name), name)


def test_the_tables_have_every_row_and_the_own_step_changes_nothing(planar_states) -> None:
    model, states = planar_states
    reference = ReferenceStep()
    stages = physics_stages.stage_costs(model, states[:1], 2, reference)
    expected = [name for name, _ in physics_stages.STAGES] + ["mj_forward", "mj_step"]
    assert list(stages) == [*expected, "integration"]
    assert all(math.isfinite(us) and math.isfinite(units) for us, units in stages.values())
    options = physics_stages.option_costs(model, states[:1], 2, reference)
    assert list(options) == ["as built", *physics_stages.OPTIONS]
    # PGS is a different solver: its stepped state differs (the table would show 0 otherwise)
    assert options["solver PGS"][2] > 0.0


def test_loop_eviction_times_the_one_call_core_after_each_work() -> None:
    core, before = loop_eviction.cases("wip_gym/PlanarTray-v0")
    core()  # raises if the task QP left its one-call path
    runs = dict.fromkeys(before, 0)

    def counted(name: str) -> object:
        def work() -> None:
            runs[name] += 1

        return work

    figures = loop_eviction.measure(
        lambda: None, {name: counted(name) for name in before}, rounds=2, calls=3
    )
    assert runs == dict.fromkeys(before, 6)
    assert all(len(values) == 2 for values in figures.values())
    with pytest.raises(ValueError, match="rounds and calls"):
        loop_eviction.measure(core, before, rounds=0, calls=3)


def test_guard_bound_cuts_the_qp_step_down_to_its_compiled_call_and_acts_alike() -> None:
    times = {}
    actions = {}
    for cut_down in (False, True):
        times[cut_down], actions[cut_down] = guard_bound.timed_loop(
            "wip_gym/PlanarTray-v0", seed=1, steps=25, cut_down=cut_down
        )
    np.testing.assert_array_equal(actions[True], actions[False])
    assert all(t.shape == (25,) and (t > 0).all() for t in times.values())
    # a QP not stepped yet (no compiled stack) is refused
    import gymnasium as gym

    from controllers.registry import make_policy

    env = gym.make("wip_gym/PlanarTray-v0")
    observation, info = env.reset(seed=1)
    policy = make_policy("unified", env)
    policy.reset(observation, info)
    with pytest.raises(RuntimeError, match="no compiled stack"):
        policy.qp._stack = None
        guard_bound.cut_down_solve(policy)
    env.close()
    policy.high_level.close()
