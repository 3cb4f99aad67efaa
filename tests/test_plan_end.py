"""The reference at and past the offline plan's end (``controllers.high_level.settling``,
docs/controllers.md §3.1).

On the claim map's aggressive drive (PlanarTray-v0, goal 1 m, ``plan.horizon_s = 3``,
``plan.a_max = none``) the plan ends 12.7 mrad back, 2.7 mm short and braking. The reference
used to step from there to the goal at ``t_f``; every MPC-based controller answered the step
with a jolt of the axle (4.5 m/s^2 for ~50 ms, against 1.9 before it). The plan is now
continued until it rests at the goal, and these tests hold the reference continuous across
``t_f`` and the jolt gone in closed loop.

Continuity is judged against the plan's own second differences (per quantity): a step of
``delta`` in a reference makes a second difference of about ``delta`` where it is; the plan's own
are ``dt^2`` times its accelerations and control rates. A continuation that only bends the
control's rate (its control is part of the plan's state: it does not jump) stays within twice
the plan's largest (its first rate is the feedback's answer to where the plan left off, not one
of the plan's own: 1.2 times the plan's largest on the aggressive drive).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from benchmarks.overrides import resolve_run
from benchmarks.rollout import rollout
from controllers.high_level.mpc import ModelPredictiveController
from controllers.high_level.planning import Plan, PlanConfig, plan_to_goal
from controllers.policy import make_robot
from controllers.simplified.wipm import WIPMParams, params_from_lambda
from controllers.simplified.wipm_problem import wipm_state

#: the claim map's aggressive drive (the --set keys of wip-bench compare)
AGGRESSIVE = {"env.goal": 1.0, "plan.horizon_s": 3.0, "plan.a_max": "none"}
#: a step is a second difference larger than this many times the plan's largest (docstring)
KINK = 2.0


def reset_state(env_id: str) -> tuple[WIPMParams, np.ndarray]:
    env = gym.make(env_id)
    observation, _ = env.reset(seed=0)
    robot = make_robot(env, "nominal")
    robot.update(observation["qpos"], observation["qvel"])
    env.close()
    return params_from_lambda(robot.wipm_parameters()), wipm_state(robot)


def aggressive_plan() -> tuple[Plan, WIPMParams]:
    params, state = reset_state("wip_gym/PlanarTray-v0")
    config = PlanConfig(horizon_s=3.0, a_max="none")
    return plan_to_goal(state, params, np.array([1.0, 0.0]), planar=True, config=config), params


def paper_plan() -> tuple[Plan, WIPMParams]:
    """The paper preset's plan on Krang: the authors' weights, 5 m straight, heading free."""
    params, state = reset_state("wip_gym/KrangTray-v0")
    plan = plan_to_goal(
        state, params, np.array([5.0, 0.0]), planar=False, config=PlanConfig.paper()
    )
    return plan, params


def assert_continuous(name: str, around: np.ndarray, plan: Plan) -> None:
    """``around``'s second differences (rows: consecutive reference states) within
    :data:`KINK` times the plan's largest, per quantity."""
    bound = KINK * np.abs(np.diff(plan.states, 2, axis=0)).max(axis=0)
    seen = np.abs(np.diff(around, 2, axis=0)).max(axis=0)
    assert np.all(seen <= bound), f"{name}: second differences {seen} against {bound}"


def reference_around(plan: Plan, start: int, count: int = 7) -> np.ndarray:
    """``count`` states of the reference from index ``start`` by :meth:`Plan.states_at`, checked
    equal to :meth:`Plan.state`'s and :meth:`Plan.window`'s."""
    indices = np.arange(start, start + count)
    around = plan.states_at(indices)
    np.testing.assert_array_equal([plan.state(i) for i in indices], around)
    np.testing.assert_array_equal(plan.window(start, count), around)
    return around


def sampled_around(plan: Plan, start: int, count: int = 7) -> np.ndarray:
    """:meth:`Plan.sample` on the grid of the reference from index ``start``."""
    times = plan.times[0] + plan.dt * np.arange(start, start + count)
    return np.array([list(plan.sample(float(t)).values()) for t in times])


@pytest.mark.parametrize("make", [aggressive_plan, paper_plan], ids=["aggressive", "paper"])
def test_the_reference_is_continuous_across_the_plans_end(make) -> None:  # noqa: ANN001
    plan, _ = make()
    N = len(plan.states) - 1
    # the aggressive plan ends away from its goal (the case), the paper's off its heading
    assert np.abs(plan.states[-1] - plan.goal_state).max() > 1e-3
    around = reference_around(plan, N - 3)
    assert_continuous("Plan.state across t_f", around, plan)
    sampled = sampled_around(plan, N - 3)
    assert_continuous("Plan.sample across t_f", sampled, plan)
    np.testing.assert_allclose(sampled, around, rtol=0, atol=1e-12)
    # the continuation ends in the rest state without a step either
    last = len(plan.reference_states) - 1
    assert last > N
    assert_continuous("Plan.state into the rest state", reference_around(plan, last - 3), plan)
    assert_continuous("Plan.sample into the rest state", sampled_around(plan, last - 3), plan)
    # which is the goal (planar); in 3-D the goal up to what the continuation does not steer:
    # x, the free heading, a sideways offset within 1 cm
    np.testing.assert_allclose(plan.reference_states[-1], plan.rest_state, rtol=0, atol=1e-9)
    aside = plan.rest_state - plan.goal_state
    if plan.planar:
        np.testing.assert_array_equal(aside, 0.0)
        assert len(plan.violations) == 1 and "arrives" in plan.violations[0]
    else:
        assert np.abs(aside[[0, 2, 3, 4, 5]]).max() == 0.0 and np.hypot(*aside[6:8]) < 0.01
        assert plan.violations == ()


def test_the_mpc_follows_the_reference_through_the_plans_end() -> None:
    """The MPC run along the reference (from its states, warm-started step after step) through
    the plan's end: its window holds the plan's continuation, so its control changes no faster
    than the plan's (it used to jump by 3.6 rad/s^2 at t_f, 40 times the plan's largest change
    of 0.09 in a step, answering the step in its window)."""
    plan, params = aggressive_plan()
    N = len(plan.states) - 1
    mpc = ModelPredictiveController(plan)
    controls = [
        mpc.step(index, plan.state(index), params).control[0]
        for index in range(N - mpc.horizon - 10, N + 10)
    ]
    largest = np.abs(np.diff(plan.controls[:, 0])).max()
    assert np.abs(np.diff(controls)).max() <= KINK * largest
    assert mpc.rejected == 0


@pytest.mark.parametrize("controller", ["unified", "decoupled-mpc"])
def test_no_jolt_at_the_plans_end_in_closed_loop(controller: str) -> None:
    """On the aggressive drive, the axle's acceleration (a finite difference of ``info["xd"]``
    at the env's step) from 0.1 s before the plan's end to 0.5 s after it stays within its
    range before (it used to spike to 4.5 m/s^2 with unified, 2.4 times the range before)."""
    env_id = "wip_gym/PlanarTray-v0"
    spec = resolve_run(env_id, [controller], overrides=AGGRESSIVE)
    speeds: list[float] = []

    def record(env: gym.Env, info: dict, step: int) -> None:
        speeds.append(float(info["xd"]))

    t_f = 3.0
    episode = rollout(
        env_id, spec.env_kwargs, controller, spec.configs[controller], 0, t_f + 0.5, record
    )
    assert episode.metrics["steps"] == len(speeds) - 1 == 3500  # the episode ran to its end
    dt = 0.001
    acceleration = np.abs(np.diff(speeds)) / dt
    t = np.arange(1, len(speeds)) * dt
    before = acceleration[t < t_f - 0.1].max()
    around = acceleration[t >= t_f - 0.1].max()
    assert around <= before, f"{controller}: {around:.3f} m/s^2 around t_f, {before:.3f} before"
