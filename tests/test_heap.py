"""``benchmarks.heap.setup_frozen``: the objects made before a timed loop are frozen for the loop
and thawed after it (also on an error, and only by the outermost freeze); the episode runner
and ``wip-bench profile`` run their loops under it."""

from __future__ import annotations

import gc
from typing import Any

import pytest

from benchmarks.heap import setup_frozen
from benchmarks.rollout import rollout
from benchmarks.speed import profile as profile_module
from benchmarks.speed.profile import profile_episode


@pytest.fixture(autouse=True)
def _thawed() -> Any:
    """Every test starts with nothing frozen, and leaves nothing frozen."""
    gc.unfreeze()
    yield
    assert gc.get_freeze_count() == 0
    gc.unfreeze()


def test_the_objects_made_before_are_frozen_in_the_block_and_thawed_after() -> None:
    before = [object() for _ in range(3)]  # a list: tracked by the collector
    with setup_frozen():
        assert gc.get_freeze_count() > 0
        assert not any(o is before for o in gc.get_objects())  # out of every generation
        made_inside = [1, 2]
        assert gc.is_tracked(made_inside)
        assert any(o is made_inside for o in gc.get_objects())  # still collectable
    assert gc.get_freeze_count() == 0
    assert any(o is before for o in gc.get_objects())  # back in a generation


def test_an_error_in_the_block_still_thaws() -> None:
    with pytest.raises(RuntimeError, match="inside"), setup_frozen():
        raise RuntimeError("inside")
    assert gc.get_freeze_count() == 0


def test_a_nested_freeze_leaves_the_thawing_to_the_outer_one() -> None:
    with setup_frozen():
        with setup_frozen():
            pass
        assert gc.get_freeze_count() > 0
    assert gc.get_freeze_count() == 0


def test_the_outermost_block_thaws_a_freeze_made_before_it() -> None:
    """The permanent generation is one per process (documented): a ``gc.freeze()`` made before
    the block is thawed with it, not leaked."""
    gc.freeze()
    with setup_frozen():
        assert gc.get_freeze_count() > 0
    assert gc.get_freeze_count() == 0


def test_the_episode_runner_steps_with_the_setup_frozen() -> None:
    counts: list[int] = []

    def on_step(env: Any, info: dict[str, Any], index: int) -> None:
        counts.append(gc.get_freeze_count())

    episode = rollout("wip_gym/PlanarTray-v0", {}, "decoupled", None, 0, 0.02, on_step=on_step)
    assert episode.metrics["steps"] == 20
    assert counts[0] == 0  # the hook after the reset, before the loop
    assert len(counts) == 21 and min(counts[1:]) > 0  # every step inside the loop


def _freeze_counts_at_the_floor(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """``gc.get_freeze_count()`` at each call of the profiler's ``floor_times`` (which it runs
    after its loop, inside the same freeze), recorded into the returned list."""
    counts: list[int] = []
    real_floor_times = profile_module.floor_times

    def floor_times(*args: Any) -> Any:
        counts.append(gc.get_freeze_count())
        return real_floor_times(*args)

    monkeypatch.setattr(profile_module, "floor_times", floor_times)
    return counts


def test_the_profiler_times_its_loop_and_floor_with_the_setup_frozen(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    counts = _freeze_counts_at_the_floor(monkeypatch)
    result = profile_episode("PlanarTray-v0", "decoupled", duration=0.02)
    assert result["steps"] == 20 and result["setup_frozen"] is True
    assert len(counts) == 1 and counts[0] > 0


def test_the_profiler_reports_the_collector_passes_in_its_loop(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A full pass forced into the fifth control step is counted, as generation 2; the other
    fields add up."""
    real_make_policy = profile_module.make_policy

    def policy_with_a_pass(*args: Any, **kwargs: Any) -> Any:
        return _FullPassAtCall(real_make_policy(*args, **kwargs), 5)

    monkeypatch.setattr(profile_module, "make_policy", policy_with_a_pass)
    result = profile_episode("PlanarTray-v0", "decoupled", duration=0.02)
    passes = result["collector_passes"]
    assert passes["by_generation"][2] == 1
    assert 0.0 < passes["longest_ms"] <= passes["total_ms"]
    assert "garbage collector in the loop" in profile_module.format_table(result)


class _FullPassAtCall:
    """A policy that runs a full collector pass before its ``at``-th call; every other
    attribute is the policy's (the profiler wraps its parts)."""

    def __init__(self, policy: Any, at: int) -> None:
        self._policy, self._at, self._calls = policy, at, 0

    def __call__(self, observation: Any) -> Any:
        self._calls += 1
        if self._calls == self._at:
            gc.collect()
        return self._policy(observation)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._policy, name)


def test_the_profiler_can_time_its_loop_without_the_freeze(monkeypatch: pytest.MonkeyPatch) -> None:
    counts = _freeze_counts_at_the_floor(monkeypatch)
    result = profile_episode("PlanarTray-v0", "decoupled", duration=0.02, freeze_setup=False)
    assert counts == [0] and result["setup_frozen"] is False
    assert "setup not frozen" in profile_module.format_table(result)
