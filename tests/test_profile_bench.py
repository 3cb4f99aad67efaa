"""``wip-bench profile``: runs, writes the documented JSON schema, and attributes time
where it was spent: a known delay put into one part shows up in that part and no other, and the
unit (``benchmarks.speed.yardstick``) agrees with a bare ``mj_step`` of Krang-v0 timed by the test.
No upper bounds on absolute times (the figures depend on the machine and its load)."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import benchmarks.speed.closed_loop_table as closed_loop_module
import benchmarks.speed.profile as profile_module
from benchmarks.cli import main
from benchmarks.speed.closed_loop_table import COLUMNS as CLOSED_LOOP_COLUMNS
from benchmarks.speed.closed_loop_table import MissingFigure, PartNotTimed, disturbed_rounds
from benchmarks.speed.closed_loop_table import comparison as closed_loop_comparison
from benchmarks.speed.closed_loop_table import figure as closed_loop_figure
from benchmarks.speed.closed_loop_table import main as closed_loop_main
from benchmarks.speed.closed_loop_table import table as closed_loop_table
from benchmarks.speed.profile import ROWS, floor_times, profile_episode, replay_step
from benchmarks.speed.yardstick import (
    REFERENCE_ENV,
    ReferenceStep,
    burst_due,
    reference_step_us,
    times_between_bursts,
)

TOP_KEYS = {
    "env",
    "preset",
    "overrides",
    "controller",
    "seed",
    "model",
    "duration_s",
    "steps",
    "control_dt_s",
    "frame_skip",
    "setup_s",
    "setup_frozen",
    "parts_timed",
    "collector_passes",
    "reference_step_us",
    "control_time_ms",
    "control_time_units",
    "per_step_us",
    "per_step_units",
    "qp_priority",
    "qp_iterations",
    "qp_paths",
    "control_over_mujoco_step",
    "low_level_over_mujoco_step",
    "real_time_factor",
    "sim_only_real_time_factor",
    "fell",
    "machine",
}
DELAY_S = 1e-3  # many times the noise of perf_counter, a few times a whole control step


def _busy_wait(seconds: float) -> None:
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        pass


def _delayed(function: Callable[..., Any]) -> Callable[..., Any]:
    def slow(*args: Any, **kwargs: Any) -> Any:
        _busy_wait(DELAY_S)
        return function(*args, **kwargs)

    return slow


class _SlowStep(gym.Wrapper):
    def step(self, action: Any) -> Any:
        _busy_wait(DELAY_S)
        return self.env.step(action)


def test_short_unified_profile_schema(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "profile.json"
    argv = ["profile", "--env", "PlanarTray-v0", "--controller", "unified", "--duration", "0.3"]
    assert main([*argv, "--json", str(path)]) == 0
    printed = capsys.readouterr().out
    assert "| mujoco_step |" in printed and "real-time factor" in printed
    assert "unit: a bare mj_step of Krang-v0" in printed
    result = json.loads(path.read_text())
    assert set(result) == TOP_KEYS
    assert result["steps"] == 300 and result["env"] == "wip_gym/PlanarTray-v0"
    assert set(result["per_step_us"]) == set(result["per_step_units"]) == set(ROWS)
    unit = result["reference_step_us"]
    assert math.isfinite(unit) and unit > 0
    for name in ROWS:  # the unified controller has every part
        stats, units = result["per_step_us"][name], result["per_step_units"][name]
        assert set(stats) == set(units) == {"mean", "median"}
        assert all(math.isfinite(v) for v in stats.values())
        assert units["median"] == pytest.approx(stats["median"] / unit)
    assert set(result["control_time_ms"]) == set(result["control_time_units"])
    assert result["control_time_units"]["p99"] == pytest.approx(
        result["control_time_ms"]["p99"] * 1e3 / unit
    )
    paths = result["qp_paths"]
    assert set(paths) == {"shortcut", "proxqp"} and paths["shortcut"] + paths["proxqp"] == 300
    # the table adds up as the schema says (means, us), and the ratios are of its rows
    mean = {name: result["per_step_us"][name]["mean"] for name in ROWS}
    measured = ("robot_model", "qp_assembly", "qp_solve", "high_level", "python_overhead")
    assert sum(mean[name] for name in measured) == pytest.approx(mean["control"], rel=1e-9)
    assert mean["low_level"] + mean["high_level"] == pytest.approx(mean["control"], rel=1e-9)
    assert mean["env_physics"] + mean["env_overhead"] == pytest.approx(mean["env_step"], rel=1e-9)
    assert mean["control"] + mean["env_step"] == pytest.approx(mean["loop"], rel=1e-9)
    assert mean["control"] == pytest.approx(result["control_time_ms"]["mean"] * 1e3, rel=1e-9)
    dt_us = result["control_dt_s"] * 1e6
    assert result["real_time_factor"] == pytest.approx(dt_us / mean["loop"], rel=1e-9)
    floor = mean["mujoco_step"]
    assert result["sim_only_real_time_factor"] == pytest.approx(dt_us / floor, rel=1e-9)
    assert result["control_over_mujoco_step"] == pytest.approx(mean["control"] / floor, rel=1e-9)
    assert result["low_level_over_mujoco_step"] == pytest.approx(
        mean["low_level"] / floor, rel=1e-9
    )
    assert result["setup_s"] > 0 and not result["fell"]
    # the closed loop's table (benchmarks.speed.closed_loop_table) reads this schema
    lines = closed_loop_table({"PlanarTray": [result, result]}).splitlines()
    units = result["control_time_units"]
    assert lines[2] == f"| control, mean | {units['mean']:.1f}, {units['mean']:.1f} | 5 |"
    parts = result["per_step_units"]
    rows_qp = parts["qp_assembly"]["mean"] + parts["qp_solve"]["mean"]
    assert f"| of which the task rows and QP (mean) | {rows_qp:.1f}, " in lines[5]
    assert lines[-1].endswith(f"{unit:.1f}, {unit:.1f}")
    # the summary: the rounds' median [min, max] (here two rounds of the same run)
    summary = closed_loop_table({"PlanarTray": [result, result]}, summary=True).splitlines()
    mean = units["mean"]
    assert summary[2] == f"| control, mean | {mean:.1f} [{mean:.1f}, {mean:.1f}] | 5 |"


def test_no_parts_times_the_loop_without_the_part_wrappers(monkeypatch: pytest.MonkeyPatch) -> None:
    """``time_parts=False`` (``--no-parts``) wraps none of the policy's methods: every controller
    part, ``python_overhead`` and ``low_level`` are null, the control and the env's physics are
    timed, and the table says why the low level's ratio is missing."""
    wrapped = []
    real_instrument = profile_module._instrument

    def instrument(policy: Any) -> Any:
        wrapped.append(policy)
        return real_instrument(policy)

    monkeypatch.setattr(profile_module, "_instrument", instrument)
    result = profile_episode("PlanarTray-v0", "unified", duration=0.05, time_parts=False)
    assert wrapped == []
    per_step = result["per_step_us"]
    for name in (*profile_module.PARTS, "python_overhead", "low_level"):
        assert per_step[name] is None, name
    assert per_step["control"]["mean"] > 0 and per_step["env_physics"]["mean"] > 0
    assert result["parts_timed"] is False and result["low_level_over_mujoco_step"] is None
    assert "parts not timed: --no-parts" in profile_module.format_table(result)
    timed = profile_episode("PlanarTray-v0", "unified", duration=0.05)
    assert len(wrapped) == 1 and timed["parts_timed"] is True
    assert timed["per_step_us"]["robot_model"] is not None


def test_a_known_delay_lands_in_its_own_part(monkeypatch: pytest.MonkeyPatch) -> None:
    """``DELAY_S`` of busy waiting put into the robot model's update and into ``env.step``: the
    profile's medians of those parts (and of what contains them) grow by at least that much,
    and the parts measured beside them do not take it (against a profile without the delay)."""
    plain = profile_episode("PlanarTray-v0", "unified", duration=0.2)
    real_make_policy = profile_module.make_policy

    def slow_policy(*args: Any, **kwargs: Any) -> Any:
        policy = real_make_policy(*args, **kwargs)
        policy.robot.update = _delayed(policy.robot.update)
        return policy

    real_make_env = profile_module.make_env
    monkeypatch.setattr(profile_module, "make_policy", slow_policy)
    monkeypatch.setattr(profile_module, "make_env", lambda *args: _SlowStep(real_make_env(*args)))
    result = profile_episode("PlanarTray-v0", "unified", duration=0.2)
    median = {name: stats["median"] * 1e-6 for name, stats in result["per_step_us"].items()}
    before = {name: stats["median"] * 1e-6 for name, stats in plain["per_step_us"].items()}
    for part in ("robot_model", "low_level", "control", "env_step", "env_overhead", "loop"):
        assert median[part] >= DELAY_S, part
    assert median["loop"] >= 2 * DELAY_S
    # not attributed to the parts timed beside the delayed ones
    parts = ("qp_assembly", "qp_solve", "python_overhead", "mujoco_step", "env_physics")
    for part in parts:
        assert median[part] - before[part] < 0.5 * DELAY_S, part


def _own_reference_us(repeats: int = 400) -> float:
    """A bare mj_step of Krang-v0's model at its reset state, timed here (not by the module)."""
    env = gym.make(REFERENCE_ENV)
    env.reset(seed=0)
    model, reset = env.unwrapped.model, env.unwrapped.data
    data = mujoco.MjData(model)
    times = []
    for _ in range(repeats + 50):
        mujoco.mj_copyData(data, model, reset)
        start = time.perf_counter()
        mujoco.mj_step(model, data)
        times.append(time.perf_counter() - start)
    env.close()
    return float(np.median(times[50:]) * 1e6)


def test_the_floor_replays_the_episodes_steps() -> None:
    """``floor_times``' steps are the env's: restoring a state recorded before ``env.step``
    and stepping it with the same action bare gives the env's next state to the bit (a
    controlled episode, cup contacts included), and bad rows are refused."""
    env = gym.make("wip_gym/KrangTray-v0")
    observation, info = env.reset(seed=0)
    base = env.unwrapped
    model, data = base.model, base.data
    policy = profile_module.make_policy("decoupled", env)
    policy.reset(observation, info)
    scratch = mujoco.MjData(model)
    size = mujoco.mj_stateSize(model, profile_module.STATE)
    states, actions = np.zeros((30, size)), np.zeros((30, model.nu))
    for n in range(30):
        action = policy(observation)
        mujoco.mj_getState(model, data, states[n], profile_module.STATE)
        actions[n] = action
        observation, *_ = env.step(action)
        seconds = replay_step(model, scratch, states[n], action, base.frame_skip)
        assert seconds > 0
        np.testing.assert_array_equal(scratch.qpos, data.qpos)
        np.testing.assert_array_equal(scratch.qvel, data.qvel)
    assert data.ncon > 0  # the cup stands on the tray: contacts were stepped
    times = floor_times(model, states, actions, base.frame_skip)
    assert times.shape == (30,) and np.all(times > 0)
    with pytest.raises(ValueError, match="integration state"):
        floor_times(model, states[:, :-1], actions, base.frame_skip)
    with pytest.raises(ValueError, match="actions must be"):
        floor_times(model, states, actions[:-1], base.frame_skip)
    env.close()


def test_a_burst_of_the_unit_is_warm_samples() -> None:
    """``ReferenceStep.burst``: ``count`` timed samples, each a bare Krang-v0 step from its
    reset state (the data after a sample is that state stepped once), bad counts refused."""
    reference = ReferenceStep()
    samples = reference.burst(5)
    assert len(samples) == 5 and all(0 < s < 1 for s in samples)
    stepped = mujoco.MjData(reference.model)
    mujoco.mj_copyData(stepped, reference.model, reference.reset_data)
    mujoco.mj_step(reference.model, stepped)
    np.testing.assert_array_equal(reference.data.qpos, stepped.qpos)
    np.testing.assert_array_equal(reference.data.qvel, stepped.qvel)
    with pytest.raises(ValueError, match=">= 1"):
        reference.burst(0)


def test_a_burst_is_due_every_so_many_steps_and_after_the_last() -> None:
    due = [step for step in range(7) if burst_due(step, 3, 7)]
    assert due == [2, 5, 6]
    assert [step for step in range(2) if burst_due(step, 50, 2)] == [1]  # a short run too
    with pytest.raises(ValueError, match=">= 1"):
        burst_due(0, 0, 5)


def test_times_between_bursts_leave_out_the_step_after_each_burst() -> None:
    """Seven timed steps, a burst after every third and after the last: the steps after a
    burst (indices 3 and 6) are run but not counted, and each burst adds its samples."""
    run: list[int] = []

    def timed(i: int) -> float:
        run.append(i)
        return float(i)

    reference = ReferenceStep()
    samples: list[float] = []
    times = times_between_bursts(timed, range(7), 7, 3, reference, samples)
    assert run == list(range(7))
    assert times == [0.0, 1.0, 2.0, 4.0, 5.0]
    assert len(samples) == 3 * 20 and all(sample > 0 for sample in samples)
    with pytest.raises(ValueError, match="warmup >= 0"):
        reference.burst(3, warmup=-1)


def test_the_envs_physics_is_its_own_part(monkeypatch: pytest.MonkeyPatch) -> None:
    """``DELAY_S`` put into the env's ``do_simulation`` lands in ``env_physics`` and not in the
    env's own work; the two add up to the env step (means)."""
    plain = profile_episode("PlanarTray-v0", "unified", duration=0.2)
    real_make_env = profile_module.make_env

    def slow_physics_env(*args: Any) -> gym.Env:
        env = real_make_env(*args)
        env.unwrapped.do_simulation = _delayed(env.unwrapped.do_simulation)
        return env

    monkeypatch.setattr(profile_module, "make_env", slow_physics_env)
    result = profile_episode("PlanarTray-v0", "unified", duration=0.2)
    parts, before = result["per_step_us"], plain["per_step_us"]
    assert parts["env_physics"]["median"] * 1e-6 >= DELAY_S
    assert plain["per_step_us"]["env_physics"]["median"] > 0
    overhead_growth = parts["env_overhead"]["median"] - before["env_overhead"]["median"]
    assert overhead_growth * 1e-6 < 0.5 * DELAY_S
    total = parts["env_physics"]["mean"] + parts["env_overhead"]["mean"]
    assert total == pytest.approx(parts["env_step"]["mean"], rel=1e-9)


class _EndsAfter(gym.Wrapper):
    """Terminates the episode at its ``steps``-th step."""

    def __init__(self, env: gym.Env, steps: int) -> None:
        super().__init__(env)
        self.left = steps

    def step(self, action: Any) -> Any:
        observation, reward, terminated, truncated, info = self.env.step(action)
        self.left -= 1
        return observation, reward, terminated or self.left == 0, truncated, info


def test_an_episode_that_ends_early_is_profiled_to_its_end(monkeypatch: pytest.MonkeyPatch) -> None:
    """An episode terminated at step 7 of 200: 7 steps profiled, with a finite, positive floor;
    a duration under one control step is refused."""
    real_make_env = profile_module.make_env
    monkeypatch.setattr(profile_module, "make_env", lambda *a: _EndsAfter(real_make_env(*a), 7))
    result = profile_episode("PlanarTray-v0", "unified", duration=0.2)
    assert result["steps"] == 7
    floor = result["per_step_us"]["mujoco_step"]
    assert all(0 < v < math.inf for v in floor.values())
    with pytest.raises(ValueError, match="less than one control step"):
        profile_episode("PlanarTray-v0", "unified", duration=1e-4)


def test_the_unit_is_a_bare_krang_step() -> None:
    """Interleaved with the test's own timing (same load), over five rounds."""
    ratios = [reference_step_us() / _own_reference_us() for _ in range(5)]
    assert 0.67 < float(np.median(ratios)) < 1.5


def test_profile_of_a_controller_without_a_task_qp(tmp_path: Path) -> None:
    path = tmp_path / "profile.json"
    argv = ["profile", "--env", "Planar-v0", "--controller", "decoupled", "--duration", "0.05"]
    assert main([*argv, "--json", str(path)]) == 0
    result = json.loads(path.read_text())
    assert set(result) == TOP_KEYS
    assert result["per_step_us"]["qp_assembly"] is None
    assert result["per_step_units"]["qp_assembly"] is None
    assert result["per_step_us"]["python_overhead"]["mean"] > 0


def test_unknown_controller_is_a_usage_error() -> None:
    with pytest.raises(SystemExit) as error:
        main(["profile", "--env", "PlanarTray-v0", "--controller", "nope"])
    assert error.value.code == 2


def test_profile_takes_compares_settings(tmp_path: Path) -> None:
    """``--set`` reaches the controller (the delayed MPC's high level) and the env, and the
    JSON records what was set; a bad key is refused before anything runs."""
    path = tmp_path / "profile.json"
    argv = ["profile", "--env", "PlanarTray-v0", "--controller", "unified", "--duration", "0.05"]
    settings = ["--set", "unified.high_level.mpc_delay_steps=3", "--set", "env.cup_friction=0.3"]
    assert main([*argv, *settings, "--json", str(path)]) == 0
    result = json.loads(path.read_text())
    assert result["overrides"] == {
        "unified.high_level.mpc_delay_steps": 3,
        "env.cup_friction": 0.3,
    }
    with pytest.raises(SystemExit) as refused:
        main([*argv, "--set", "unified.high_level.no_such_field=1"])
    assert refused.value.code == 2


def test_a_strict_stack_is_reported_as_such(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """With strict priorities the profile reports DAQP's levels, not ProxQP's iteration
    counts (which the strict stack does not make)."""
    path = tmp_path / "profile.json"
    argv = ["profile", "--env", "PlanarTray-v0", "--controller", "unified", "--duration", "0.05"]
    assert main([*argv, "--set", "unified.priority=strict", "--json", str(path)]) == 0
    result = json.loads(path.read_text())
    assert result["qp_priority"] == "strict"
    assert result["qp_iterations"] is None and result["qp_paths"] is None
    assert "strict priorities, DAQP's levels" in capsys.readouterr().out


def test_closed_loop_table_refuses_a_profile_without_a_task_qp() -> None:
    result = {"per_step_units": {"qp_assembly": None, "qp_solve": None}}
    with pytest.raises(ValueError, match="no task QP"):
        closed_loop_figure(result, ("per_step_units", "qp_assembly", "mean"))


def test_closed_loop_comparison_shows_each_columns_rounds_before_and_after() -> None:
    def profile(control: float, unit: float, physics: bool = True) -> dict[str, Any]:
        part = {"mean": 1.0, "median": 1.0}
        parts = dict.fromkeys(("robot_model", "qp_assembly", "qp_solve", "high_level"), part)
        parts |= dict.fromkeys(("env_step", "env_overhead", "loop", "mujoco_step"), part)
        if physics:  # False: a --base revision's profile from before env_physics existed
            parts["env_physics"] = part
        return {
            "control_time_units": {"mean": control, "p99": 3 * control},
            "per_step_units": parts,
            "real_time_factor": 2.0,
            "reference_step_us": unit,
        }

    before = {"KrangTray": [profile(20.0, 15.0), profile(18.0, 16.0), profile(19.0, 14.0)]}
    after = {"KrangTray": [profile(15.0, 15.5)]}
    lines = closed_loop_comparison(before, after).splitlines()
    assert lines[0] == "| per 1 ms step, units | KrangTray before | KrangTray after | target |"
    assert lines[2] == "| control, mean | 19.0 [18.0, 20.0] | 15.0 | 5 |"
    assert lines[3] == "| control, p99 | 57.0 [54.0, 60.0] | 45.0 | 12 |"
    assert "| of which the task rows and QP (mean) | 2.0 [2.0, 2.0] | 2.0 |  |" in lines
    assert "| of which its physics (mean) | 1.0 [1.0, 1.0] | 1.0 |  |" in lines
    assert lines[-1] == "unit (bare mj_step of Krang-v0): 14.0 to 16.0 us"
    # a base from before the warm yardstick: its missing figure is "-", and the table says
    # that its figures were measured another way
    lacking = {"KrangTray": [profile(20.0, 15.0, physics=False)]}
    old = closed_loop_comparison(lacking, after).splitlines()
    assert "| of which its physics (mean) | - | 1.0 |  |" in old
    assert "predate the warm yardstick" in old[-1]
    # ... but a run of this checkout without the figure is an error, not a "-"
    with pytest.raises(MissingFigure):
        closed_loop_comparison(before, lacking)
    # a null part in the middle of a path is refused as such
    nulled = profile(15.0, 15.5)
    nulled["per_step_units"]["env_physics"] = None
    with pytest.raises(ValueError, match="null"):
        closed_loop_figure(nulled, ("per_step_units", "env_physics", "mean"))


def test_closed_loop_columns_without_part_timers_show_no_parts() -> None:
    """A column run with ``--no-parts`` has its control, env and loop figures and ``-`` for the
    controller's parts, in the table and in a comparison; a part of a profile with the parts
    timed but null (a controller without a QP) is still refused; a base revision whose
    profiler predates ``--no-parts`` runs no such column."""
    part = {"mean": 1.0, "median": 1.0}
    timed_parts = ("robot_model", "qp_assembly", "qp_solve", "high_level")
    untimed: dict[str, Any] = {
        "control_time_units": {"mean": 4.9, "p99": 20.0},
        "per_step_units": {
            **dict.fromkeys((*timed_parts, "python_overhead", "low_level")),
            **dict.fromkeys(("env_step", "env_physics", "mujoco_step", "env_overhead"), part),
            "loop": {"mean": 8.2, "median": 8.0},
        },
        "real_time_factor": 16.0,
        "reference_step_us": 7.0,
        "parts_timed": False,
    }
    with pytest.raises(PartNotTimed):
        closed_loop_figure(untimed, ("per_step_units", "qp_assembly", "mean"))
    with pytest.raises(PartNotTimed):
        closed_loop_figure(untimed, ("per_step_units", "robot_model", "mean"))
    lines = closed_loop_table({"KrangTray, no part timers": [untimed, untimed]}).splitlines()
    assert lines[2] == "| control, mean | 4.9, 4.9 | 5 |"
    assert "| of which the robot model (mean) | - |  |" in lines
    assert "| of which the task rows and QP (mean) | - |  |" in lines
    assert "| closed loop, mean | 8.2, 8.2 | 8 |" in lines
    compared = closed_loop_comparison({"K": [untimed]}, {"K": [untimed, untimed]}).splitlines()
    assert "| of which the high level (mean) | - | - |  |" in compared
    assert "| closed loop, mean | 8.2 | 8.2 [8.2, 8.2] | 8 |" in compared
    timed_null = {**untimed, "parts_timed": True}
    with pytest.raises(ValueError, match="no task QP"):
        closed_loop_figure(timed_null, ("per_step_units", "qp_assembly", "mean"))
    # the default columns have both envs without the timers; a tree without the flag none
    untimed_columns = [c for c in CLOSED_LOOP_COLUMNS if "--no-parts" in c[2]]
    assert {c[1] for c in untimed_columns} == {"wip_gym/KrangTray-v0", "wip_gym/PlanarTray-v0"}
    assert closed_loop_module._runs_in(closed_loop_module.REPO, untimed_columns[0][2])
    assert closed_loop_module._runs_in(Path("/nonexistent"), ())
    assert not closed_loop_module._runs_in(Path("/nonexistent"), untimed_columns[0][2])


def test_closed_loop_rounds_on_a_disturbed_machine_are_flagged() -> None:
    """A round whose physics in the loop, over the same steps warm, is over 1.1 times its
    column's least is named, in its column and version; the others are not."""

    def profile(physics: float, floor: float = 2.0) -> dict[str, Any]:
        part = {"mean": 1.0, "median": 1.0}
        parts = dict.fromkeys(
            ("robot_model", "qp_assembly", "qp_solve", "high_level", "env_step"), part
        )
        parts |= dict.fromkeys(("env_overhead", "loop"), part)
        parts["env_physics"] = {"mean": physics, "median": physics}
        parts["mujoco_step"] = {"mean": floor, "median": floor}
        return {
            "control_time_units": {"mean": 5.0, "p99": 10.0},
            "per_step_units": parts,
            "real_time_factor": 2.0,
            "reference_step_us": 7.0,
        }

    # two of three rounds disturbed: the least, not the median, is the reference
    column = [profile(3.0), profile(3.2), profile(2.5)]
    assert disturbed_rounds({"KrangTray, d = 5": column}, "after ") == [
        "after KrangTray, d = 5: rounds 0, 1"
    ]
    # within 10 %, or the same ratio at another floor: nothing
    assert disturbed_rounds({"KrangTray": [profile(2.5), profile(2.7), profile(5.0, 4.0)]}) == []
    quiet = {"KrangTray": [profile(2.5), profile(2.6)]}
    note = closed_loop_comparison(quiet, {"KrangTray": column[:2] + [profile(2.5)]})
    assert note.splitlines()[-1].endswith("after KrangTray: rounds 0, 1")
    assert "disturbed" not in closed_loop_comparison(quiet, quiet)


def test_closed_loop_table_refuses_an_unknown_base(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as raised:
        closed_loop_main(["--base", "no-such-revision-here", "--rounds", "1"])
    assert raised.value.code == 2
    assert "no-such-revision-here" in capsys.readouterr().err
