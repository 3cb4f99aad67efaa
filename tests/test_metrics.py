"""The episode metrics (benchmarks.metrics) on synthetic info sequences against hand-computed
values, the summary statistics against textbook values, and the seed rule."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.metrics import (
    LOSS_ORDER,
    EpisodeMetrics,
    path_length,
    step_loss,
    tilt_from_quaternion,
)
from benchmarks.seeding import episode_seed
from benchmarks.statistics import describe, rate, wilson_interval

DT = 0.001


def info(offset: tuple[float, float, float], use: float = 0.1, **extra: object) -> dict:
    """A tray task's info row with the cup at ``offset`` in the tray frame."""
    row = {
        "goal_distance": 1.0,
        "xd": 0.2,
        "fallen": False,
        "ee_error": 0.01,
        "tray_tilt_deg": 1.0,
        "cup_offset": np.array(offset),
        "cup_on_tray": True,
        "cup_friction_use": use,
    }
    row.update(extra)
    return row


UPRIGHT = {"cup_pose": np.array([0.0, 0.0, 0.04, 1.0, 0.0, 0.0, 0.0])}


def tilted(degrees: float) -> dict:
    """An observation with the cup rotated ``degrees`` about the tray's x axis."""
    half = math.radians(degrees) / 2
    return {"cup_pose": np.array([0.0, 0.0, 0.04, math.cos(half), math.sin(half), 0.0, 0.0])}


def test_slip_distance_is_the_path_length_and_slipping_time_counts_steps_at_099() -> None:
    metrics = EpisodeMetrics(DT, info((0.0, 0.0, 0.04)), UPRIGHT)
    # cup path: +1 cm x, +2 cm y, still, then straight back to the start
    for offset, use in (
        ((0.01, 0.0, 0.04), 0.5),
        ((0.01, 0.02, 0.04), 0.99),
        ((0.01, 0.02, 0.04), 1.0),
        ((0.0, 0.0, 0.04), 0.98),
        ((0.0, 0.0, 0.04), 1.0),
    ):
        metrics.update(info(offset, use), UPRIGHT)
    result = metrics.result()
    assert result["cup_slip_distance_m"] == pytest.approx(0.01 + 0.02 + math.hypot(0.01, 0.02))
    assert result["slipping_time_s"] == pytest.approx(3 * DT)  # 0.99, 1.0, 1.0
    assert result["max_cup_friction_use"] == 1.0
    assert result["cup_kept"] is True and result["cup_lost_at_s"] is None
    assert result["tray_slip_distance_m"] == 0.0  # no tray_offset: welded
    assert result["steps"] == 5 and result["sim_time_s"] == pytest.approx(5 * DT)


def test_a_tipped_cup_is_lost_and_its_slip_stops_counting_there() -> None:
    metrics = EpisodeMetrics(DT, info((0.0, 0.0, 0.04)), UPRIGHT)
    metrics.update(info((0.01, 0.0, 0.04)), tilted(10.0))
    metrics.update(info((0.03, 0.0, 0.04)), tilted(40.0))  # beyond 30 deg: lost on step 2
    metrics.update(info((0.5, 0.0, 0.04)), tilted(90.0))  # falling: not counted as slip
    result = metrics.result()
    assert result["cup_kept"] is False
    assert result["cup_lost_at_s"] == pytest.approx(2 * DT)
    assert result["cup_slip_distance_m"] == pytest.approx(0.03)
    assert result["max_cup_tilt_deg"] == pytest.approx(90.0)
    assert result["success"] is False


def test_env_keys_take_precedence_when_present() -> None:
    # the env's own cup_upright / cup_on_plate / tray_on_hand / tray_offset when it reports them
    start = info((0.0, 0.0, 0.04), tray_offset=np.zeros(3), cup_tilt_deg=0.0)
    metrics = EpisodeMetrics(DT, start, None)
    metrics.update(
        info(
            (0.0, 0.0, 0.04),
            tray_offset=np.array([0.0, 0.003, 0.0]),
            cup_tilt_deg=5.0,
            cup_upright=True,
            cup_on_plate=True,
            tray_on_hand=True,
        )
    )
    metrics.update(
        info(
            (0.0, 0.0, 0.04),
            tray_offset=np.array([0.004, 0.003, 0.0]),
            cup_tilt_deg=5.0,
            cup_upright=True,
            cup_on_plate=False,
            tray_on_hand=False,
        )
    )
    result = metrics.result()
    assert result["tray_slip_distance_m"] == pytest.approx(0.007)
    assert result["cup_kept"] is False and result["cup_lost_at_s"] == pytest.approx(2 * DT)
    assert result["tray_kept"] is False
    assert result["max_cup_tilt_deg"] == 5.0


def _stream(*steps: dict) -> dict:
    """The metrics of a tray task's episode whose steps change the info row by ``steps``
    (a free tray's keys present, the cup still on the plate's centre, at the goal)."""
    base = {"tray_on_hand": True, "cup_upright": True, "cup_on_plate": True, "tray_offset": 0.0}

    def row(change: dict) -> dict:
        merged = {**base, **change}
        merged["tray_offset"] = np.full(3, merged["tray_offset"])
        return info((0.0, 0.0, 0.04), goal_distance=0.0, xd=0.0, **merged)

    metrics = EpisodeMetrics(DT, row({}), UPRIGHT)
    for change in steps:
        metrics.update(row(change), UPRIGHT)
    return metrics.result()


def test_an_episode_kept_to_the_end_is_carried_and_its_success_needs_the_goal() -> None:
    result = _stream({}, {}, {})
    assert result["outcome"] == "carried" and result["outcome_time_s"] is None
    assert result["carried"] is True
    assert result["cup_kept"] is True and result["success"] is True
    far = EpisodeMetrics(DT, info((0.0, 0.0, 0.04)), UPRIGHT)  # 1 m from the goal
    far.update(info((0.0, 0.0, 0.04)), UPRIGHT)
    assert far.result()["carried"] is True and far.result()["success"] is False


@pytest.mark.parametrize(
    ("steps", "outcome", "at_step"),
    [
        # one loss, then recovery or worse: the first one is the outcome
        (({}, {"fallen": True}, {}), "fell", 2),
        (({}, {"tray_on_hand": False}, {"tray_on_hand": True}), "tray_lost", 2),
        (({}, {}, {"cup_on_plate": False}, {"fallen": True}), "cup_lost", 3),
        (({"cup_upright": False}, {"tray_on_hand": False}), "cup_lost", 1),
        (({}, {"tray_on_hand": False}, {"fallen": True, "cup_on_plate": False}), "tray_lost", 2),
        # two or three losses first seen on one step: the cause is named
        (({}, {"fallen": True, "tray_on_hand": False, "cup_on_plate": False}), "fell", 2),
        (({}, {"fallen": True, "cup_upright": False}), "fell", 2),
        (({"tray_on_hand": False, "cup_on_plate": False},), "tray_lost", 1),
        (({"tray_on_hand": False, "cup_on_tray": False},), "tray_lost", 1),
    ],
)
def test_the_outcome_is_the_first_loss_and_its_time(
    steps: tuple[dict, ...], outcome: str, at_step: int
) -> None:
    result = _stream(*steps)
    assert result["outcome"] == outcome
    assert result["outcome_time_s"] == pytest.approx(at_step * DT)
    assert result["carried"] is False and result["success"] is False
    # the cup is not kept from the first step the tray leaves the hand or the cup the plate
    # (a fall alone leaves it kept: that is the outcome's, and fell's, to say)
    if outcome != "fell":
        assert result["cup_kept"] is False
        assert result["cup_lost_at_s"] == pytest.approx(at_step * DT)


def test_a_cup_riding_a_dropped_tray_is_not_kept() -> None:
    """The cup still upright on the plate in the tray's frame, the tray off the hand: lost."""
    result = _stream({}, {"tray_on_hand": False, "tray_offset": -0.05}, {"tray_on_hand": False})
    assert result["tray_kept"] is False and result["cup_kept"] is False
    assert result["cup_lost_at_s"] == pytest.approx(2 * DT)
    assert (result["outcome"], result["carried"], result["success"]) == ("tray_lost", False, False)
    # the tray's slip path stops with the loss, like the cup's
    assert result["tray_slip_distance_m"] == pytest.approx(0.05 * math.sqrt(3))


def test_step_loss_names_the_cause_first() -> None:
    assert step_loss(False) is None
    assert LOSS_ORDER == ("fell", "tray_lost", "cup_lost")
    for fallen, on_hand, on_tray in np.ndindex(2, 2, 2):
        losses = (fallen, not on_hand, not on_tray)
        shown = [name for name, lost in zip(LOSS_ORDER, losses, strict=True) if lost]
        assert step_loss(bool(fallen), bool(on_hand), bool(on_tray)) == (shown or [None])[0]


def test_without_a_tray_the_outcome_is_balanced_or_fell_and_carried_is_none() -> None:
    reset = {"goal_distance": 0.0, "xd": 0.0, "fallen": False}
    up = EpisodeMetrics(DT, reset)
    up.update(reset)
    assert up.result()["outcome"] == "balanced" and up.result()["carried"] is None
    assert up.result()["success"] is True
    down = EpisodeMetrics(DT, reset)
    down.update(reset)
    down.update({**reset, "fallen": True})
    result = down.result()
    assert (result["outcome"], result["outcome_time_s"]) == ("fell", pytest.approx(2 * DT))
    assert result["carried"] is None and result["success"] is False


def test_time_at_the_actuator_limit_and_goal_metrics() -> None:
    low, high = np.array([-10.0, -5.0]), np.array([10.0, 5.0])
    reset = {"goal_distance": 0.1, "xd": 0.0, "fallen": False}
    metrics = EpisodeMetrics(DT, reset, None, low, high)
    for action, distance, speed in (
        ([10.0, 0.0], 0.10, 0.2),  # at the upper bound
        ([0.0, -5.0], 0.04, 0.01),  # at the lower bound
        ([9.0, 4.0], 0.03, 0.01),
    ):
        metrics.update(
            {"goal_distance": distance, "xd": -speed, "fallen": False}, None, np.array(action), 1e-4
        )
    result = metrics.result()
    assert result["time_at_actuator_limit_s"] == pytest.approx(2 * DT)
    assert result["time_to_goal_s"] == pytest.approx(2 * DT)  # within 5 cm and slow from step 2
    assert result["final_goal_error_m"] == pytest.approx(0.03)
    assert result["cup_kept"] is None and result["max_cup_friction_use"] is None
    assert result["success"] is True


def test_tilt_from_quaternion_matches_the_rotated_axis() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        w, x, y, z = q
        # third column of the rotation matrix: the rotated z axis
        axis_z = np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])
        expected = math.degrees(math.acos(np.clip(axis_z[2], -1, 1)))
        assert tilt_from_quaternion(q) == pytest.approx(expected, abs=1e-9)
    assert path_length(np.zeros((1, 3))) == 0.0


def test_wilson_interval_against_textbook_values() -> None:
    low, high = wilson_interval(5, 10)
    assert (low, high) == (pytest.approx(0.2366, abs=1e-4), pytest.approx(0.7634, abs=1e-4))
    z2 = 1.959963984540054**2
    assert wilson_interval(0, 10) == (0.0, pytest.approx(z2 / (10 + z2)))
    assert wilson_interval(10, 10)[1] == 1.0  # exactly: round-off must not put it inside
    with pytest.raises(ValueError):
        wilson_interval(3, 2)


def test_describe_and_rate_report_spread_and_skip_absent_values() -> None:
    stats = describe([1.0, None, 3.0])
    # the sample standard deviation (ddof 1): sqrt(((1 - 2)^2 + (3 - 2)^2) / (2 - 1))
    assert stats == {"mean": 2.0, "std": pytest.approx(2**0.5), "min": 1.0, "max": 3.0, "n": 2}
    assert describe([4.0]) == {"mean": 4.0, "std": 0.0, "min": 4.0, "max": 4.0, "n": 1}
    assert describe([None, None]) is None
    with pytest.raises(ValueError, match="NaN"):
        describe([1.0, float("nan")])
    flags = rate([True, False, None, True])
    assert flags is not None and flags["rate"] == pytest.approx(2 / 3) and flags["n"] == 3
    assert flags["ci95"][0] < 2 / 3 < flags["ci95"][1]
    assert rate([None]) is None


def test_episode_seed_is_base_plus_index() -> None:
    assert [episode_seed(5, i) for i in range(3)] == [5, 6, 7]
    with pytest.raises(ValueError, match="index"):
        episode_seed(0, -1)
    with pytest.raises(ValueError, match="outside"):
        episode_seed(2**32 - 1, 1)


def test_a_cup_moved_a_known_distance_over_the_tray_gives_that_slip_distance() -> None:
    """MuJoCo as referee: the cup is placed 1 mm further along the tray's x axis before each of
    50 env steps (at rest, in contact); the metric from the env's info is the 5 cm path, up to
    the physics of the 1 ms steps between placements."""
    import gymnasium as gym
    import mujoco

    import wip_gym  # noqa: F401

    env = gym.make("wip_gym/PlanarTray-v0", max_episode_steps=-1, terminate_on_cup_loss=False)
    observation, reset_info = env.reset(seed=0)
    base = env.unwrapped
    model, data = base.model, base.data
    qpos = model.jnt_qposadr[model.joint("cup").id]
    dof = model.jnt_dofadr[model.joint("cup").id]
    tray = model.body("tray").id
    start = np.array(reset_info["cup_offset"])
    metrics = EpisodeMetrics(base.dt, reset_info, observation)
    steps, distance = 50, 0.05
    for k in range(1, steps + 1):
        target = start + np.array([distance * k / steps, 0.0, 0.0])
        data.qpos[qpos : qpos + 3] = data.xpos[tray] + data.xmat[tray].reshape(3, 3) @ target
        data.qvel[dof : dof + 6] = 0.0
        mujoco.mj_forward(model, data)
        observation, _, _, _, info = env.step(np.zeros(env.action_space.shape))
        metrics.update(info, observation)
    env.close()
    result = metrics.result()
    assert result["cup_slip_distance_m"] == pytest.approx(distance, abs=1e-4)
    assert result["cup_kept"] is True
