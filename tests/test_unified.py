"""The hierarchical (unified) controller closed loop: the cup carried to the goal."""

from __future__ import annotations

import numpy as np
import pytest

import wip_gym  # noqa: F401
from benchmarks.rollout import rollout
from controllers.hierarchical import HierarchicalConfig, tilt_toward


def test_the_waiters_lead_must_lie_inside_the_mpc_horizon() -> None:
    """A negative lead wrapped to the prediction's end; one at or past the horizon (1 s) read
    past it or divided by a zero span; a zero window is one MPC step each side."""
    for lead, window in ((-0.01, 0.1), (1.0, 0.1), (1.05, 0.1), (0.1, -0.1)):
        with pytest.raises(ValueError, match=r"tray_lead_s must be in \[0, the MPC horizon"):
            HierarchicalConfig(tray_lead_s=lead, tray_window_s=window)
    HierarchicalConfig(tray_lead_s=0.99, tray_window_s=0.0)


def test_tilt_toward_the_specific_force() -> None:
    R = tilt_toward(np.array([9.81, 0.0]), max_tilt_deg=90.0)
    normal = R @ np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(normal, np.array([1.0, 0.0, 1.0]) / np.sqrt(2), atol=1e-12)
    bounded = tilt_toward(np.array([9.81, 0.0]), max_tilt_deg=10.0) @ np.array([0.0, 0.0, 1.0])
    assert np.degrees(np.arccos(bounded[2])) == pytest.approx(10.0)
    np.testing.assert_allclose(tilt_toward(np.zeros(2), 20.0), np.eye(3))


def run(env_id: str, goal, mode: str, seconds: float, **env_kwargs) -> dict:
    """One episode through the one rollout (its metrics are the ones compare reports)."""
    name = "unified" if mode == "level" else "unified-waiter"
    config = HierarchicalConfig(tray_mode=mode)
    episode = rollout(env_id, {"goal": goal, **env_kwargs}, name, config, 0, seconds)
    metrics = episode.metrics
    assert metrics["sim_time_s"] == pytest.approx(seconds), metrics  # not ended early
    assert episode.policy.plan.violations == ()
    assert metrics["counters"]["qp_failures"] == 0 and metrics["counters"]["mpc_rejections"] == 0
    return metrics


@pytest.fixture(scope="module")
def planar_runs() -> dict[str, dict]:
    return {
        mode: run("wip_gym/PlanarTray-v0", 2.0, mode, 9.0) for mode in ("level", "specific_force")
    }


@pytest.mark.parametrize("mode", ["level", "specific_force"])
def test_planar_tray_reaches_the_goal_with_the_cup(planar_runs: dict, mode: str) -> None:
    metrics = planar_runs[mode]
    assert metrics["goal_reached"]  # within 5 cm and 5 cm/s of the goal to the episode's end
    assert metrics["cup_kept"]


def test_level_mode_keeps_the_tray_level(planar_runs: dict) -> None:
    assert planar_runs["level"]["max_tray_tilt_deg"] < 5.0


def test_waiter_comes_less_close_to_slipping(planar_runs: dict) -> None:
    waiter, level = planar_runs["specific_force"], planar_runs["level"]
    assert waiter["max_cup_friction_use"] < level["max_cup_friction_use"]


def test_unified_keeps_the_cup_when_a_payload_appears_in_the_hand() -> None:
    # 3 kg in the hand at 2.5 s (mid-drive), unknown to the nominal model: without the
    # estimate of the hand tasks' unmodelled acceleration the tray tipped 38 deg and the cup
    # fell at 3.5 s (README); 6 s covers the braking that tipped it and the stop
    info = run("wip_gym/PlanarTray-v0", 2.0, "level", 6.0, payload_mass=3.0, payload_time=2.5)
    assert info["cup_kept"] and info["max_tray_tilt_deg"] < 5.0


# KrangTray-v0: the goal ahead, and 1.5 m to either side (the plan turns toward the goal
# while it drives). 7.5 s: every run has arrived and settled by 7 s (goal distance under
# 1.5 cm, speed under 2 cm/s, measured).
KRANG_GOALS = [(2.0, 0.0), (2.0, 1.5), (2.0, -1.5)]
KRANG_SECONDS = 7.5


@pytest.fixture(scope="module")
def krang_run():
    """One Krang episode per (goal, mode), run on first use and shared by the tests."""
    runs: dict[tuple, dict] = {}

    def get(goal: tuple[float, float], mode: str) -> dict:
        if (goal, mode) not in runs:
            runs[goal, mode] = run("wip_gym/KrangTray-v0", goal, mode, KRANG_SECONDS)
        return runs[goal, mode]

    return get


@pytest.mark.parametrize("goal", KRANG_GOALS)
def test_krang_level_tray_reaches_the_goal_with_the_cup(krang_run, goal) -> None:
    metrics = krang_run(goal, "level")
    assert metrics["goal_reached"] and metrics["final_goal_error_m"] < 0.05
    assert metrics["cup_kept"] and metrics["max_tray_tilt_deg"] < 5.0


@pytest.mark.parametrize("goal", KRANG_GOALS)
def test_krang_waiter_reaches_the_goal_and_comes_less_close_to_slipping(krang_run, goal) -> None:
    waiter = krang_run(goal, "specific_force")
    assert waiter["goal_reached"] and waiter["final_goal_error_m"] < 0.05
    assert waiter["cup_kept"]
    assert waiter["max_cup_friction_use"] < krang_run(goal, "level")["max_cup_friction_use"]


@pytest.mark.parametrize(
    ("env_id", "delay", "solutions"),
    [("wip_gym/PlanarTray-v0", 0, 6), ("wip_gym/KrangTray-v0", 4, 6)],
)
def test_the_waiters_tray_target_made_once_per_mpc_solution_is_the_per_step_one(
    env_id: str, delay: int, solutions: int
) -> None:
    """The waiter's tray target depends on the MPC solution in use only: made once per solution,
    the closed loop's actions are those of making it every step, to the bit (planar, and 3-D
    with the MPC beside the loop, whose solutions come into use mid-period)."""
    import dataclasses

    import gymnasium as gym

    from controllers.registry import default_config, make_policy

    config = default_config("unified-waiter")
    config = dataclasses.replace(
        config, high_level=dataclasses.replace(config.high_level, mpc_delay_steps=delay)
    )
    actions: dict[bool, list[np.ndarray]] = {}
    made: dict[bool, int] = {}
    for every_step in (False, True):
        env = gym.make(env_id)
        observation, info = env.reset(seed=2)
        policy = make_policy("unified-waiter", env, config)
        policy.reset(observation, info)
        predicted = policy._predicted_acceleration
        made[every_step] = 0

        def counted(robot: object, predicted: object = predicted, key: bool = every_step) -> object:
            made[key] += 1
            return predicted(robot)  # type: ignore[operator]

        policy._predicted_acceleration = counted
        actions[every_step] = []
        for _ in range(60):
            if every_step:
                policy._tray_target = None  # forget it: made again at this step
            action = policy(observation)
            actions[every_step].append(action)
            observation, *_ = env.step(action)
        env.close()
        policy.high_level.close()
    np.testing.assert_array_equal(np.array(actions[False]), np.array(actions[True]))
    assert made == {False: solutions, True: 60}  # one MPC solution per 10 ms, 60 steps of 1 ms


@pytest.mark.parametrize("env_id", ["wip_gym/PlanarTray-v0", "wip_gym/KrangTray-v0"])
def test_diagnostics_wipm_state_and_reference_are_the_per_step_ones(env_id: str) -> None:
    """The diagnostics keep the robot update's scalars and the MPC index per step and make the
    WIPM state and the plan's state of them when read: equal, to the bit, to the robot's
    ``wipm_state()`` and the plan's ``state(index)`` taken at each step (past the plan's end
    too: the goal state); a second episode's diagnostics start empty."""
    import gymnasium as gym

    from controllers.registry import make_policy

    env = gym.make(env_id, goal=0.05 if env_id.startswith("wip_gym/Planar") else (0.05, 0.0))
    observation, info = env.reset(seed=1)
    policy = make_policy("unified", env)
    policy.reset(observation, info)
    states, references, indices = [], [], []
    past_end = len(policy.plan.states) + 5
    for step in range(120):
        if step == 60:  # past the plan's end from here (the goal state)
            policy.high_level._step = past_end * policy.high_level.steps_per_mpc
        action = policy(observation)
        states.append(policy.robot.wipm_state())
        indices.append(policy._ref.mpc_index)
        references.append(policy.plan.state(policy._ref.mpc_index).copy())
        observation, *_ = env.step(action)
    diagnostics = policy.diagnostics
    assert indices[-1] >= len(policy.plan.states)  # some steps past the end
    np.testing.assert_array_equal(diagnostics["wipm_state"], np.array(states))
    np.testing.assert_array_equal(diagnostics["wipm_reference"], np.array(references))
    assert list(diagnostics)[:3] == ["t", "wipm_state", "wipm_reference"]
    with pytest.raises(ValueError, match="update scalars"):
        policy.robot.wipm_states(np.zeros((2, 3)))
    plan, policy.plan = policy.plan, None
    with pytest.raises(RuntimeError, match="plan is gone"):
        policy.diagnostics  # noqa: B018  (the property raises)
    policy.plan = plan
    policy.reset(*env.reset(seed=2))
    assert policy.diagnostics == {}


@pytest.mark.parametrize("name", ["unified", "unified-waiter"])
def test_the_closed_loop_keeps_its_compiled_stack(name: str) -> None:
    """In the closed loop nothing structural changes between control steps (the references and
    the waiter's tray target are parameters, copied in at every step), so every step after
    reset takes the compiled path on the stack reset built: a per-step change of structure
    would build a stack at every step, unseen but for the time."""
    import gymnasium as gym

    from controllers.registry import make_policy

    env = gym.make("wip_gym/KrangTray-v0")
    observation, info = env.reset(seed=0)
    policy = make_policy(name, env)
    policy.reset(observation, info)
    qp = policy.qp
    stack = qp._stack
    for _ in range(40):
        observation, *_ = env.step(policy(observation))
        assert qp.compiled and qp._stack is stack
    env.close()
    policy.high_level.close()
