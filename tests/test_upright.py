"""``unified-upright`` (controllers/upright.py): registered, told the scenario's cup (or another
friction), and in closed loop on the map's aggressive drive at friction 0.05 it carries the cup
where the paper's controller loses it."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from benchmarks.overrides import resolve_run
from benchmarks.rollout import run_configured_episode
from controllers.high_level.planning import PlanConfig
from controllers.registry import controller_names, default_config, make_policy
from controllers.upright import UprightConfig, UprightController

#: the claim map's aggressive drive (benchmarks/sweeps/claim_map.toml), no rim
AGGRESSIVE = {
    "env.goal": 1.0,
    "plan.horizon_s": 3.0,
    "plan.a_max": "none",
    "env.tray_rim": 0.0,
    "env.cup_friction": 0.05,
}


def _episode(name: str, seconds: float, overrides: dict, seed: int = 0):
    spec = resolve_run("wip_gym/PlanarTray-v0", [name], None, overrides=overrides)
    env = gym.make("wip_gym/PlanarTray-v0", **spec.env_kwargs)
    observation, info = env.reset(seed=seed)
    policy = make_policy(name, env, spec.configs[name])
    policy.reset(observation, info)
    uses, kept = [], True
    for _ in range(int(round(seconds / env.unwrapped.dt))):
        observation, _, terminated, _, info = env.step(policy(observation))
        uses.append(info["cup_friction_use"])
        kept = kept and info["cup_on_tray"] and not info["fallen"]
        if terminated:
            break
    return policy, kept, np.array(uses)


def test_registered_with_its_own_low_level_and_the_papers_plan_in_the_paper_preset():
    assert "unified-upright" in controller_names()
    config = default_config("unified-upright")
    assert isinstance(config, UprightConfig) and config.priority == "weighted"
    assert config.hand_observer_bandwidth is None and config.ee_position_weight == (0.1, 10, 10)
    paper = default_config("unified-upright", preset="paper")
    assert paper.high_level.plan == PlanConfig.paper()
    assert paper.theta_weight == config.theta_weight  # its own low level, not the authors'


@pytest.mark.parametrize("told", [None, 0.091])
def test_it_plans_with_the_scenarios_cup_or_the_friction_it_is_told(told):
    overrides = {"env.cup_friction": 0.07}
    if told is not None:
        overrides["unified-upright.carried.friction"] = told
    policy, _, _ = _episode("unified-upright", 0.01, overrides)
    assert isinstance(policy, UprightController) and policy.name == "unified-upright"
    assert policy.balance is not None
    assert policy.balance.friction == (0.07 if told is None else told)
    margin = policy.config.carried.margin
    assert policy.balance.planning_friction == pytest.approx((1 - margin) * policy.balance.friction)
    assert set(policy.controller_counters()) >= {"object_active_steps", "object_relaxed_steps"}


def test_without_a_cup_it_is_the_unified_controller_with_its_weights():
    env = gym.make("wip_gym/Planar-v0")
    observation, info = env.reset(seed=0)
    policy = make_policy("unified-upright", env)
    policy.reset(observation, info)
    assert policy.balance is None and policy.tray_reference is None
    for _ in range(300):
        observation, _, terminated, _, info = env.step(policy(observation))
        assert not terminated
    assert policy.controller_counters()["object_active_steps"] == 0


def test_bad_settings_are_refused():
    for field, value in (
        ("tangential_weight", -1.0),
        ("slack_weight", 0.0),
        ("drive_weight", np.nan),
    ):
        with pytest.raises(ValueError, match=field):
            UprightConfig(**{field: value})


def test_it_carries_the_cup_on_the_aggressive_drive_where_unified_loses_it():
    """PlanarTray-v0's aggressive drive at friction 0.05, seed 0, through its acceleration
    phase (3 s): ``unified-upright`` keeps the cup on the tray, its friction use's 99th
    percentile under 0.8; the paper's level tray (``unified``) does not keep it."""
    policy, kept, uses = _episode("unified-upright", 3.0, AGGRESSIVE)
    assert kept, "unified-upright lost the cup"
    assert np.percentile(uses, 99) < 0.8, np.percentile(uses, 99)
    assert policy.controller_counters()["qp_fallbacks"] == 0
    _, kept_unified, uses_unified = _episode("unified", 3.0, AGGRESSIVE)
    assert not kept_unified or uses_unified.max() >= 1.0


def test_strict_priorities_carry_the_cup_through_the_acceleration():
    """``priority="strict"``: the object's rows are a level under the balance (DAQP), the drive
    row and the hand's forward row traded with the posture in the last level; seed 0 of the
    aggressive drive at friction 0.05 keeps the cup through the acceleration phase (3 s),
    without a fallback, its friction use's 99th percentile under 0.8 (docs/upright.md §5)."""
    overrides = {**AGGRESSIVE, "unified-upright.priority": "strict"}
    policy, kept, uses = _episode("unified-upright", 3.0, overrides)
    assert policy.config.priority == "strict"
    assert kept, "strict unified-upright lost the cup or fell"
    assert np.percentile(uses, 99) < 0.8, np.percentile(uses, 99)
    assert policy.controller_counters()["qp_fallbacks"] == 0


def test_the_strict_stack_trades_the_drive_and_the_hands_forward_rows_with_the_posture():
    """``strict_posture_rows`` names the rows given to the strict stack's posture level: the
    drive row and each hand's forward position row (its weight the least of its three)."""
    for rows, expected in (((), 0), (("drive",), 1), (("hand_forward",), 1), (None, 2)):
        overrides = {**AGGRESSIVE, "unified-upright.priority": "strict"}
        if rows is not None:
            overrides["unified-upright.strict_posture_rows"] = list(rows)
        policy, _, _ = _episode("unified-upright", 0.01, overrides)
        posture_rows = policy._posture_rows  # noqa: SLF001 - what the QP is given
        assert len(posture_rows) == expected
        for task, indices in posture_rows:
            if task is policy._drive:  # noqa: SLF001
                assert indices == (0,)
            else:
                assert task in policy._hands and indices == (0,)  # noqa: SLF001
                assert np.argmin(task.weights()) == 0 and task.weights()[0] == 0.1
    with pytest.raises(ValueError, match="strict_posture_rows"):
        UprightConfig(strict_posture_rows=("posture",))  # type: ignore[arg-type]
    assert dataclasses.replace(policy.config, priority="weighted").priority == "weighted"


def test_it_reaches_the_goal_with_the_plan_on_the_aggressive_drive():
    """The claim map's cell (friction 0.05, no cap, 5 % mass randomisation), seed 0, 8 s: the
    cup carried and the goal criterion (benchmarks/metrics.py) met by 4.0 s, the issue's
    target, where the plan's own reference meets it at 3.7 s (docs/controllers.md §3.1). With
    the drift loop's former gains (kp 4, kv 4, lead 0.1) it met it at 5.3 s, oscillating about
    the goal with the body (docs/upright.md §5)."""
    overrides = {**AGGRESSIVE, "env.mass_randomization": 0.05, "env.tray_attachment": "welded"}
    row = run_configured_episode("wip_gym/PlanarTray-v0", "unified-upright", overrides, 0, 8.0)
    assert row["outcome"] == "carried", row["outcome"]
    assert row["cup_friction_use_p99"] < 0.8, row["cup_friction_use_p99"]
    assert row["goal_reached"] and row["time_to_goal_s"] <= 4.0, row["time_to_goal_s"]


@pytest.mark.parametrize("env_id", ["wip_gym/PlanarTray-v0", "wip_gym/KrangTray-v0"])
def test_one_hand_and_two_hands_follow_their_own_tray_gains(env_id):
    """A tray on one hand takes ``tray``, one on two hands (Krang) ``two_hand_tray``, with its
    hand pair and tangential weight; each set read from the config, not fixed in the code."""
    config = dataclasses.replace(
        default_config("unified-upright"),
        tray=dataclasses.replace(default_config("unified-upright").tray, kp=2.5),
        two_hand_tray=dataclasses.replace(default_config("unified-upright").two_hand_tray, kv=3.5),
    )
    env = gym.make(env_id)
    observation, info = env.reset(seed=0)
    policy = make_policy("unified-upright", env, config)
    policy.reset(observation, info)
    two_hands = env_id == "wip_gym/KrangTray-v0"
    gains = policy.tray_reference.gains
    assert gains == (config.two_hand_tray if two_hands else config.tray)
    assert (gains.kv == 3.5) if two_hands else (gains.kp == 2.5)
    assert (policy.hand_pair is not None) == two_hands
    tangential = [t for t in policy._qp_tasks if type(t).__name__ == "TangentialForceTask"]
    weight = config.two_hand_tangential_weight if two_hands else config.tangential_weight
    assert [t.weight for t in tangential] == [weight]


@pytest.mark.parametrize("share", [True, False])
def test_the_free_tray_weighs_on_both_hands_of_the_nominal_model(share):
    """On Krang's free tray the nominal model carries the tray on both grippers, each its
    measured share (``share_tray_weight``; controllers/high_level/tray_seat.py); off, or with a
    welded tray, the whole tray hangs on the left gripper as in every other controller's."""
    config = dataclasses.replace(default_config("unified-upright"), share_tray_weight=share)
    for attachment in ("free", "welded"):
        env = gym.make("wip_gym/KrangTray-v0", tray_attachment=attachment)
        observation, info = env.reset(seed=0)
        policy = make_policy("unified-upright", env, config)
        policy.reset(observation, info)
        m = policy.robot.model
        tray = m.body("tray").id
        shares = [b for b in range(m.nbody) if m.body(b).name.startswith("tray_share_")]
        env_tray = env.unwrapped.model.body_mass[env.unwrapped.model.body("tray").id]
        assert m.body_mass[tray] + sum(m.body_mass[b] for b in shares) == pytest.approx(env_tray)
        if share and attachment == "free":
            assert [m.body(b).name for b in shares] == ["tray_share_right_gripper"]
            assert 0.3 * env_tray < m.body_mass[shares[0]] < 0.7 * env_tray
            assert m.body_subtreemass[0] == pytest.approx(m.body_mass.sum())
        else:
            assert shares == []


@pytest.mark.parametrize("share", [True, False])
def test_the_shared_tray_keeps_the_cup_where_the_right_hand_sagged(share):
    """KrangTray-v0 in the paper's configuration at friction 0.05 (no rim, 5 % mass
    randomisation), seed 8: with the whole tray on the left gripper the unmodelled half on the
    right arm sags its hand and turns the tray about the heading, and the cup slides off at
    1.06 s; with the weight shared it stays (docs/upright.md §6)."""
    overrides = {
        "env.tray_rim": 0.0,
        "env.cup_friction": 0.05,
        "env.mass_randomization": 0.05,
        "unified-upright.share_tray_weight": share,
    }
    row = run_configured_episode(
        "wip_gym/KrangTray-v0", "unified-upright", overrides, 8, 1.5, preset="paper"
    )
    assert (row["outcome"] == "carried") == share, row["outcome"]
