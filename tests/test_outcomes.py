"""An episode's outcome on the real envs (docs/metrics.md §1): a dropped tray, a cup pushed off
the plate and a fall, each the outcome the env's own per-step flags give, at the step they
first show it, with the env's loss-termination on and off.

The first-loss rule itself (ties, recoveries, no tray) is tested on synthetic info streams in
``tests/test_metrics.py``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from benchmarks.metrics import EpisodeMetrics
from benchmarks.overrides import resolve_run
from benchmarks.rollout import rollout

PLANAR = "wip_gym/PlanarTray-v0"
CONTROLLER = "decoupled-lqr"  # the quickest to set up; any controller drives these episodes
DURATION_S = 3.0
CUP_PUSH_N = 3.0  # along world x on the 0.05 kg cup: 60 m/s^2, far beyond mu g at mu = 0.3
CUP_PUSH_STEP = 200


class FlagTrace:
    """The rollout's ``on_step`` hook: each step's loss flags as the env reports them, and
    optionally a force on the cup from step :data:`CUP_PUSH_STEP` on."""

    def __init__(self, push_cup: bool = False) -> None:
        self.push_cup = push_cup
        self.rows: list[dict[str, bool]] = []

    def __call__(self, env: gym.Env, info: dict[str, Any], index: int) -> None:
        if index == 0:
            return
        self.rows.append(
            {key: bool(info[key]) for key in ("fallen", "tray_on_hand", "cup_on_tray")}
        )
        if self.push_cup and index == CUP_PUSH_STEP:
            base = env.unwrapped
            base.data.xfrc_applied[base.model.body("cup").id, 0] = CUP_PUSH_N

    def first(self, key: str, value: bool) -> int:
        """The first step (1-based) whose ``key`` is ``value``."""
        return next(k for k, row in enumerate(self.rows, 1) if row[key] is value)


def _episode(overrides: dict[str, Any], trace: FlagTrace, terminate: bool) -> dict[str, Any]:
    spec = resolve_run(
        PLANAR, [CONTROLLER], overrides={**overrides, "env.terminate_on_cup_loss": terminate}
    )
    episode = rollout(
        PLANAR, spec.env_kwargs, CONTROLLER, spec.configs[CONTROLLER], 0, DURATION_S, on_step=trace
    )
    return episode.metrics


@pytest.mark.parametrize("terminate", [True, False])
def test_a_dropped_tray_is_tray_lost_and_its_cup_not_kept(terminate: bool) -> None:
    """A free tray on a hand of friction 0.01 slides off as the robot drives; the cup still
    rides it when it leaves the hand, and is not kept from that step."""
    trace = FlagTrace()
    overrides = {"env.tray_attachment": "free", "env.tray_friction": 0.01}
    metrics = _episode(overrides, trace, terminate)
    dropped = trace.first("tray_on_hand", False)
    assert trace.rows[dropped - 1]["cup_on_tray"]  # upright on the plate, on a dropped tray
    assert not any(row["fallen"] for row in trace.rows[:dropped])
    assert metrics["outcome"] == "tray_lost" and metrics["carried"] is False
    assert metrics["outcome_time_s"] == pytest.approx(dropped * 1e-3)
    assert metrics["cup_kept"] is False and metrics["tray_kept"] is False
    assert metrics["cup_lost_at_s"] == metrics["outcome_time_s"]
    assert metrics["success"] is False
    # termination on: the episode ends there; off: it runs to the end
    assert metrics["steps"] == (dropped if terminate else round(DURATION_S / 1e-3))


def test_termination_does_not_change_the_outcome_of_a_dropped_tray() -> None:
    overrides = {"env.tray_attachment": "free", "env.tray_friction": 0.01}
    on = _episode(overrides, FlagTrace(), True)
    off = _episode(overrides, FlagTrace(), False)
    assert (on["outcome"], on["outcome_time_s"]) == (off["outcome"], off["outcome_time_s"])
    assert off["steps"] > on["steps"]


@pytest.mark.parametrize("terminate", [True, False])
def test_a_cup_pushed_off_the_plate_is_cup_lost(terminate: bool) -> None:
    trace = FlagTrace(push_cup=True)
    metrics = _episode({}, trace, terminate)
    lost = trace.first("cup_on_tray", False)
    assert lost > CUP_PUSH_STEP
    assert not any(row["fallen"] or not row["tray_on_hand"] for row in trace.rows[:lost])
    assert metrics["outcome"] == "cup_lost" and metrics["carried"] is False
    assert metrics["outcome_time_s"] == pytest.approx(lost * 1e-3) == metrics["cup_lost_at_s"]
    assert metrics["tray_kept"] is True and metrics["cup_kept"] is False
    assert metrics["steps"] == (lost if terminate else round(DURATION_S / 1e-3))


@pytest.mark.parametrize(
    ("env_id", "fall_angle", "carried"),
    [
        ("wip_gym/Planar-v0", 0.8, None),  # the default fall angle; no tray: nothing carried
        # zero torque drops the arm, and the cup, by about 0.3 s; a fall counted from a small
        # angle of theta comes first
        (PLANAR, 0.05, False),
        ("wip_gym/KrangTray-v0", 0.005, False),
    ],
)
def test_zero_action_is_a_fall(env_id: str, fall_angle: float, carried: bool | None) -> None:
    env = gym.make(env_id, max_episode_steps=-1, fall_angle=fall_angle)
    observation, info = env.reset(seed=0)
    metrics = EpisodeMetrics(env.unwrapped.dt, info, observation)
    fallen, kept = [], []
    for _ in range(2000):
        observation, _, terminated, _, info = env.step(np.zeros(env.action_space.shape))
        metrics.update(info, observation)
        fallen.append(bool(info["fallen"]))
        kept.append(bool(info.get("cup_on_tray", True) and info.get("tray_on_hand", True)))
        if terminated:
            break
    env.close()
    result = metrics.result()
    fell_at = fallen.index(True) + 1  # the step the env first reports the fall
    assert all(kept[: fell_at - 1])  # the cup and tray held until then
    assert result["outcome"] == "fell" and result["fell"] is True
    assert result["outcome_time_s"] == pytest.approx(fell_at * env.unwrapped.dt)
    assert result["carried"] is carried and result["success"] is False
