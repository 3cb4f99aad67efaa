"""Every default controller (the model-based ones, ``default_controller_names``) drives both
tray envs through the one rollout, in both tray attachments, for a short episode: it does not
fall, keeps the cup, and every metric is finite.
"""

from __future__ import annotations

import math

import pytest

from benchmarks.overrides import resolve_run
from benchmarks.rollout import rollout, run_configured_episode
from controllers.registry import default_controller_names

DURATION_S = 1.0
ENVS = ("wip_gym/PlanarTray-v0", "wip_gym/KrangTray-v0")


@pytest.mark.parametrize("attachment", ["welded", "free"])
@pytest.mark.parametrize("env_id", ENVS)
@pytest.mark.parametrize("controller", default_controller_names())
def test_every_controller_carries_the_cup_on_both_tray_envs(
    controller: str, env_id: str, attachment: str
) -> None:
    overrides: dict[str, object] = {"env.tray_attachment": attachment}
    spec = resolve_run(env_id, [controller], overrides=overrides)
    episode = rollout(env_id, spec.env_kwargs, controller, spec.configs[controller], 0, DURATION_S)
    m = episode.metrics
    assert m["steps"] == round(DURATION_S / 0.001), m  # neither a fall nor a lost cup ended it
    assert m["fell"] is False and m["cup_kept"] is True and m["tray_kept"] is True
    for key in (
        "max_cup_friction_use",
        "slipping_time_s",
        "cup_slip_distance_m",
        "tray_slip_distance_m",
        "max_tray_tilt_deg",
        "time_at_actuator_limit_s",
    ):
        assert math.isfinite(m[key]) and m[key] >= 0.0, key
    # the paper's controller: no slip at all (unified-upright's free tray on Krang slips for a
    # step: docs/upright.md §6)
    if controller in ("unified", "unified-waiter"):
        assert m["max_cup_friction_use"] < 1.0 and m["slipping_time_s"] == 0.0
    if attachment == "welded":
        assert m["tray_slip_distance_m"] == 0.0
    assert all(math.isfinite(v) for v in m["counters"].values())


def test_run_configured_episode_returns_a_json_row() -> None:
    import json

    row = run_configured_episode(
        "PlanarTray-v0", "decoupled", {"env.cup_friction": "0.5", "unified.theta_kp": 1.0}, 3, 0.2
    )
    assert json.loads(json.dumps(row)) == row
    assert row["seed"] == 3 and row["env_arguments"]["cup_friction"] == 0.5
    assert row["overrides"] == {"env.cup_friction": 0.5, "unified.theta_kp": 1.0}
    assert row["config"]["plan"]["horizon_s"] > 0 and row["steps"] == 200


def test_the_rollout_runs_past_the_registered_time_limit() -> None:
    """The envs truncate themselves at their ``time_limit`` (25 s); an episode's duration is
    the rollout's, so the rollout's env carries no TimeLimit and no time limit of its own."""
    import gymnasium as gym

    spec = resolve_run("wip_gym/Planar-v0", ["decoupled"])
    episode = rollout(
        "wip_gym/Planar-v0", {}, "decoupled", spec.configs["decoupled"], 0, 0.01, keep_env=True
    )
    env = episode.env
    assert env is not None
    wrappers = []
    while isinstance(env, gym.Wrapper):
        wrappers.append(type(env).__name__)
        env = env.env
    assert "TimeLimit" not in wrappers, wrappers
    assert env.time_limit is None
    episode.env.close()


def test_an_episode_that_raises_is_a_failure_of_the_run_not_of_the_arguments(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A controller's NaN action raises in the env; the rollout names the episode and step,
    and the CLI (which turns ValueError into a usage message, exit 2) lets it through."""
    import numpy as np

    from benchmarks.rollout import EpisodeError
    from controllers import registry

    class NaNPolicy:
        counters: dict[str, float] = {}

        def reset(self, observation, info) -> None:
            pass

        def __call__(self, observation):
            return np.full(2, np.nan)

    monkeypatch.setattr(registry, "make_policy", lambda *args, **kwargs: NaNPolicy())
    with pytest.raises(EpisodeError, match=r"step 1 .*t = 0.000 s"):
        rollout("wip_gym/WIP-v0", {}, "decoupled", None, 0, 0.1)
    assert not issubclass(EpisodeError, ValueError)


def test_the_rollout_reports_simulated_seconds_and_compare_counts_them() -> None:
    """``progress`` hears the simulated time every ``PROGRESS_INTERVAL_S`` and at the end
    (through ``compare_episode``, as ``(task index, seconds)``); compare's bar of simulated
    seconds adds each episode's advance once, never past its duration, and counts an episode
    that ended early (a fall) as whole."""
    import queue

    from benchmarks.compare import _SimulatedSeconds
    from benchmarks.episode import compare_episode
    from benchmarks.rollout import PROGRESS_INTERVAL_S

    spec = resolve_run("wip_gym/Planar-v0", ["decoupled"])
    reports: queue.SimpleQueue[tuple[int, float]] = queue.SimpleQueue()
    compare_episode(
        3, "wip_gym/Planar-v0", {}, "decoupled", spec.configs["decoupled"], 0, 0.35,
        progress=reports,
    )  # fmt: skip
    heard = []
    while not reports.empty():
        heard.append(reports.get())
    assert [index for index, _ in heard] == [3] * 4
    seconds = [s for _, s in heard]
    expected = [PROGRESS_INTERVAL_S, 2 * PROGRESS_INTERVAL_S, 3 * PROGRESS_INTERVAL_S, 0.35]
    assert seconds == pytest.approx(expected, abs=1e-12)

    bar = _SimulatedSeconds(tasks=2, duration=1.0)
    try:
        for report in [(0, 0.1), (1, 0.2), (0, 0.3), (0, 0.3), (1, 5.0)]:
            bar(report)  # a repeated report adds nothing; one past the end stops at it
        assert bar.done_ms == [300, 1000] and bar.bar.n == 1300
        bar.finish(0)  # episode 0 ended at 0.3 s (a fall): its whole second counts
        assert bar.done_ms == [1000, 1000] and bar.bar.n == bar.bar.total == 2000
    finally:
        bar.close()
