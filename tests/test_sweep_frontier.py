"""The sweep's frontiers (docs/sweeps.md §5) and outcome rates, without Ray: the critical value
on hand-made rates, the ``[[frontier]]`` spec's checks, ``summary.json``'s rows and rates,
``report.md``'s tables, the heatmaps' marks, and ``--dry-run``'s frontier lines and calibrated
estimate."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from benchmarks.cli import main
from benchmarks.sweep import estimate
from benchmarks.sweep.frontier import critical_value, frontier_rows
from benchmarks.sweep.plots import frontier_marks
from benchmarks.sweep.report import write_report
from benchmarks.sweep.spec import Frontier, SpecError, SweepSpec, parse_spec
from benchmarks.sweep.stats import wilson_interval

NO_PLOTS = ('axes = ["env.cup_friction", "plan.a_max"]', "axes = []")  # a quicker report
SPEC = """
env = "wip_gym/PlanarTray-v0"
controllers = ["decoupled", "unified"]
duration = 1.0
seeds = 4
[grid]
"env.cup_friction" = [0.05, 0.1, 0.2, 0.4]
"plan.a_max" = ["cup_safe", 1.5, 2.5, "none"]
"env.tray_attachment" = ["welded", "free"]
[report]
axes = ["env.cup_friction", "plan.a_max"]
[[frontier]]
axis = "env.cup_friction"
toward = "low"
rate = 0.75
[[frontier]]
axis = "plan.a_max"
toward = "high"
rate = 0.5
"""


# ------------------------------------------------------------------ the critical value
@pytest.mark.parametrize(
    ("rates", "critical"),
    [
        ([1.0, 1.0, 0.5, 0.0], "c"),  # monotone: holds up to c, at the threshold 0.5
        ([1.0, 0.4, 0.9, 1.0], "a"),  # b fails: c and d, though holding, do not count
        ([0.3, 1.0, 1.0, 1.0], None),  # the easiest fails: nothing holds
        ([0.0, 0.0, 0.0, 0.0], None),
        ([1.0, 1.0, 1.0, 1.0], "d"),  # every value holds: the hardest
        ([1.0, None, 1.0, 1.0], "a"),  # a value without episodes does not hold
    ],
)
def test_the_critical_value_is_the_hardest_value_held_from_the_easiest_on(
    rates: list[float | None], critical: str | None
) -> None:
    assert critical_value(["a", "b", "c", "d"], rates, 0.5) == critical


def test_critical_value_rejects_mismatched_lengths() -> None:
    with pytest.raises(ValueError, match="3 values against 2 rates"):
        critical_value([1, 2, 3], [1.0, 1.0], 0.5)


def test_toward_orders_the_listed_values() -> None:
    values = ("cup_safe", 1.5, 2.5, "none")
    assert Frontier("plan.a_max", "high", 0.5).easiest_first(values) == list(values)
    assert Frontier("plan.a_max", "low", 0.5).easiest_first(values) == list(reversed(values))


# ------------------------------------------------------------------ hand-made summaries
def _cells(spec: SweepSpec, carried: Callable[[dict[str, Any], str], float | None]) -> list[dict]:
    """Summary cells whose carried rates are ``carried(cell parameters, controller)``."""
    return [
        {
            "parameters": cell,
            "controllers": {
                name: {"carried_rate": carried(cell, name)} for name in spec.controllers
            },
        }
        for cell in spec.cells()
    ]


def _rates_by_friction(table: dict[float, float]) -> Callable[[dict[str, Any], str], float]:
    return lambda cell, name: table[cell["env.cup_friction"]]


def test_frontier_rows_cover_every_controller_and_combination_of_the_other_axes() -> None:
    spec = parse_spec(SPEC, validate_env=False)
    friction = {0.05: 0.0, 0.1: 0.5, 0.2: 1.0, 0.4: 1.0}

    def carried(cell: dict[str, Any], name: str) -> float:
        # unified holds one friction step further, and only while welded
        if name == "unified" and cell["env.tray_attachment"] == "welded":
            return 1.0 if cell["env.cup_friction"] >= 0.1 else 0.0
        # "none" fails everywhere; a_max holds otherwise where the friction does
        return 0.0 if cell["plan.a_max"] == "none" else friction[cell["env.cup_friction"]]

    rows = frontier_rows(spec, _cells(spec, carried))
    # 2 frontiers x 4 values of the axis not on it... x 2 attachments x 2 controllers
    assert len(rows) == 2 * 4 * 2 * 2
    assert all(
        set(r) == {"controller", "axis", "toward", "rate", "fixed", "critical", "rates"}
        for r in rows
    )
    friction_rows = [r for r in rows if r["axis"] == "env.cup_friction"]
    assert {json.dumps(r["fixed"], sort_keys=True) for r in friction_rows} == {
        json.dumps({"plan.a_max": a, "env.tray_attachment": t}, sort_keys=True)
        for a in ("cup_safe", 1.5, 2.5, "none")
        for t in ("welded", "free")
    }
    for r in friction_rows:
        assert list(r["rates"]) == ["0.05", "0.1", "0.2", "0.4"]  # the listed order
        if r["fixed"]["plan.a_max"] == "none" and not (
            r["controller"] == "unified" and r["fixed"]["env.tray_attachment"] == "welded"
        ):
            assert r["critical"] is None  # fails at the easiest friction, 0.4
        elif r["controller"] == "unified" and r["fixed"]["env.tray_attachment"] == "welded":
            assert r["critical"] == 0.1
        else:
            assert r["critical"] == 0.2  # 0.1 carries 0.5 < 0.75
    a_max_rows = [r for r in rows if r["axis"] == "plan.a_max"]
    for r in a_max_rows:
        assert list(r["rates"]) == ["cup_safe", "1.5", "2.5", "none"]
        assert r["toward"] == "high" and r["rate"] == 0.5
    decoupled_at = {
        r["fixed"]["env.cup_friction"]: r["critical"]
        for r in a_max_rows
        if r["controller"] == "decoupled" and r["fixed"]["env.tray_attachment"] == "free"
    }
    # "none" fails; at 0.05 even cup_safe fails; at 0.1 the rate 0.5 holds (>= 0.5)
    assert decoupled_at == {0.05: None, 0.1: 2.5, 0.2: 2.5, 0.4: 2.5}


def test_toward_high_on_a_numeric_axis_reads_it_the_other_way() -> None:
    spec = parse_spec(
        SPEC.replace('toward = "low"\nrate = 0.75', 'toward = "high"\nrate = 0.75'),
        validate_env=False,
    )
    friction = {0.05: 1.0, 0.1: 0.8, 0.2: 0.7, 0.4: 1.0}
    rows = frontier_rows(spec, _cells(spec, _rates_by_friction(friction)))
    criticals = {r["critical"] for r in rows if r["axis"] == "env.cup_friction"}
    assert criticals == {0.1}  # 0.2 falls short, and caps 0.4


# ------------------------------------------------------------------ spec checks
BAD_FRONTIERS = {
    "unknown axis": ('axis = "plan.a_max"', 'axis = "env.goal"', "env.goal"),
    "bad toward": ('toward = "high"', 'toward = "up"', "toward 'up'"),
    "rate above 1": ("rate = 0.5", "rate = 1.5", "rate 1.5"),
    "rate below 0": ("rate = 0.5", "rate = -0.1", "rate -0.1"),
    "rate not a number": ("rate = 0.5", 'rate = "most"', "rate 'most'"),
    "rate a boolean": ("rate = 0.5", "rate = true", "rate True"),
    "unknown key": ("rate = 0.5", "rate = 0.5\nlevel = 2", "level"),
    "missing key": ("rate = 0.5\n", "\n", "'rate'"),
    "numbers out of order": ("0.05, 0.1, 0.2, 0.4]", "0.05, 0.2, 0.1, 0.4]", "increasing"),
    "mixed numbers out of order": ('"cup_safe", 1.5, 2.5,', '"cup_safe", 2.5, 1.5,', "increasing"),
    "repeated": (
        "rate = 0.5\n",
        'rate = 0.5\n[[frontier]]\naxis = "plan.a_max"\ntoward = "high"\nrate = 0.5\n',
        "repeats",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_FRONTIERS))
def test_a_bad_frontier_is_a_spec_error_naming_it(case: str) -> None:
    old, new, named = BAD_FRONTIERS[case]
    assert SPEC.count(old) == 1
    with pytest.raises(SpecError, match="frontier") as error:
        parse_spec(SPEC.replace(old, new), validate_env=False)
    assert named in str(error.value)


def test_a_frontier_on_an_axis_of_arrays_or_as_one_table_is_refused() -> None:
    arrays = """
env = "wip_gym/KrangTray-v0"
controllers = ["decoupled"]
duration = 1.0
seeds = 1
[grid]
"env.goal" = [[1.0, 0.0], [2.0, 0.0]]
[[frontier]]
axis = "env.goal"
toward = "high"
rate = 0.9
"""
    with pytest.raises(SpecError, match="cannot be ordered"):
        parse_spec(arrays, validate_env=False)
    single = arrays.replace("[[frontier]]", "[frontier]")
    with pytest.raises(SpecError, match=r"\[\[frontier\]\] table"):
        parse_spec(single, validate_env=False)


def test_a_bad_frontier_exits_2_and_a_trayless_env_has_none(tmp_path: Path, capsys) -> None:
    path = tmp_path / "spec.toml"
    path.write_text(SPEC.replace('toward = "high"', 'toward = "harder"'))
    with pytest.raises(SystemExit) as exit_info:
        main(["sweep", str(path), "--dry-run", "--no-calibration"])
    assert exit_info.value.code == 2 and "toward 'harder'" in capsys.readouterr().err
    trayless = """
env = "wip_gym/Planar-v0"
controllers = ["decoupled"]
duration = 1.0
seeds = 1
[grid]
"env.goal" = [1.0, 2.0]
[[frontier]]
axis = "env.goal"
toward = "high"
rate = 0.9
"""
    with pytest.raises(SpecError, match="no tray"):
        parse_spec(trayless)


# ------------------------------------------------------------------ summary and report
def _store(
    directory: Path, spec: SweepSpec, carried: Callable[[dict[str, Any], str, int], bool]
) -> None:
    """A store of ok rows whose ``carried`` (and outcome) is ``carried(cell, controller,
    replicate)``; every episode at the goal."""
    with open(directory / "episodes.jsonl", "w") as f:
        for e in spec.episodes():
            kept = carried(e.cell, e.controller, e.replicate)
            metrics = {
                "carried": kept,
                "outcome": "carried" if kept else "cup_lost",
                "goal_reached": True,
                "success": kept,
                "max_cup_friction_use": 0.5,
            }
            row = {
                "id": e.id,
                "status": "ok",
                "git_commit": "aaa",
                "git_dirty": False,
                "package_version": "0.1.0",
                "replicate": e.replicate,
                "metrics": metrics,
            }
            f.write(json.dumps(row) + "\n")


def test_the_summary_and_report_hold_carried_rates_outcomes_and_the_frontier(
    tmp_path: Path,
) -> None:
    spec = parse_spec(SPEC, validate_env=False)
    # unified carries 3 of 4 at 0.1 and everything above; decoupled from 0.2 on, 2 of 4 at 0.1
    needed = {"unified": {0.05: 4, 0.1: 1, 0.2: 0, 0.4: 0}, "decoupled": {0.05: 4, 0.1: 2}}

    def carried(cell: dict[str, Any], name: str, replicate: int) -> bool:
        return replicate >= needed[name].get(cell["env.cup_friction"], 0)

    _store(tmp_path, spec, carried)
    summary = write_report(spec, tmp_path)
    saved = json.loads((tmp_path / "summary.json").read_text())
    assert saved["frontier"] == json.loads(json.dumps(summary["frontier"]))
    cell = next(
        c
        for c in summary["cells"]
        if c["parameters"]
        == {"env.cup_friction": 0.1, "plan.a_max": 1.5, "env.tray_attachment": "free"}
    )
    unified = cell["controllers"]["unified"]
    assert unified["carried_rate"] == 0.75
    assert unified["carried_ci95"] == pytest.approx(list(wilson_interval(3, 4)))
    assert unified["success_rate"] == 0.75 and unified["goal_reached_rate"] == 1.0
    assert unified["outcomes"] == {"carried": 3, "cup_lost": 1}
    paired = cell["paired"][0]
    assert (paired["a"], paired["b"]) == ("decoupled", "unified")
    assert paired["carried_rate_difference"]["estimate"] == pytest.approx(0.5 - 0.75)
    friction_rows = {
        (r["controller"], r["fixed"]["plan.a_max"], r["fixed"]["env.tray_attachment"]): r
        for r in summary["frontier"]
        if r["axis"] == "env.cup_friction"
    }
    assert len(friction_rows) == 2 * 4 * 2
    for (name, _, _), row in friction_rows.items():
        assert row["critical"] == (0.1 if name == "unified" else 0.2)  # rate 0.75
        assert row["rates"]["0.05"] == 0.0 and row["rates"]["0.4"] == 1.0
    # decoupled's 0.5 at 0.1 holds for the a_max frontier's rate 0.5: every a_max holds there
    a_max = [r for r in summary["frontier"] if r["axis"] == "plan.a_max"]
    assert {r["critical"] for r in a_max if r["fixed"]["env.cup_friction"] == 0.05} == {None}
    assert {r["critical"] for r in a_max if r["fixed"]["env.cup_friction"] == 0.1} == {"none"}
    report = (tmp_path / "report.md").read_text()
    assert "## Frontiers" in report
    assert (
        '| env.cup_friction | low | 0.75 | plan.a_max=1.5, env.tray_attachment="free" '
        "| unified | 0.1 | 0.05: 0.00, 0.1: 0.75, 0.2: 1.00, 0.4: 1.00 |" in report
    )
    assert "| carried | 95 % CI | success | 95 % CI | goal |" in report
    assert "carried 3, cup_lost 1" in report
    for name in ("heatmap_carried_rate", "heatmap_success_rate"):
        assert (tmp_path / f"{name}_tray_attachment=free.png").stat().st_size > 0
    # the heatmap (x friction, y a_max) outlines each row's critical friction, and each
    # column's critical a_max
    marks = frontier_marks(spec, summary, {"env.tray_attachment": "free"}, "unified")
    friction_marks = {(i, j) for i, j, k in marks if k == 0}
    assert friction_marks == {(i, 1) for i in range(4)}  # 0.1 in every a_max row
    a_max_marks = {(i, j) for i, j, k in marks if k == 1}
    assert a_max_marks == {(3, j) for j in (1, 2, 3)}  # "none" from friction 0.1 on


def test_without_a_frontier_the_summary_has_an_empty_list_and_no_table(tmp_path: Path) -> None:
    spec = parse_spec(SPEC.split("[[frontier]]")[0].replace(*NO_PLOTS), validate_env=False)
    _store(tmp_path, spec, lambda cell, name, replicate: True)
    assert write_report(spec, tmp_path)["frontier"] == []
    assert "## Frontiers" not in (tmp_path / "report.md").read_text()


def test_rows_without_outcomes_give_null_carried_rates(tmp_path: Path) -> None:
    """A store written before outcomes existed (or an env without a tray): no carried rate,
    and so no critical value."""
    spec = parse_spec(SPEC.replace(*NO_PLOTS), validate_env=False)
    _store(tmp_path, spec, lambda cell, name, replicate: True)
    lines = (tmp_path / "episodes.jsonl").read_text().splitlines()
    stripped = []
    for line in lines:
        row = json.loads(line)
        del row["metrics"]["carried"], row["metrics"]["outcome"]
        stripped.append(json.dumps(row))
    (tmp_path / "episodes.jsonl").write_text("\n".join(stripped) + "\n")
    summary = write_report(spec, tmp_path)
    first = summary["cells"][0]["controllers"]["decoupled"]
    assert first["carried_rate"] is None and first["carried_ci95"] is None
    assert first["outcomes"] == {} and first["success_rate"] == 1.0
    assert {r["critical"] for r in summary["frontier"]} == {None}


# ------------------------------------------------------------------ dry run and estimate
def test_dry_run_prints_the_frontiers_without_calibrating(tmp_path: Path, capsys) -> None:
    path = tmp_path / "spec.toml"
    path.write_text(SPEC)
    assert main(["sweep", str(path), "--dry-run", "--no-calibration", "--workers", "2"]) == 0
    text = capsys.readouterr().out
    assert (
        "frontier env.cup_friction: carried rate >= 0.75, harder toward low (easiest to "
        "hardest: 0.4 -> 0.2 -> 0.1 -> 0.05); 16 rows" in text
    )
    assert 'harder toward high (easiest to hardest: "cup_safe" -> 1.5 -> 2.5 -> "none")' in text
    assert "256 episodes to run on 2 workers (no time estimate" in text
    assert list(tmp_path.iterdir()) == [path]


def test_the_estimate_adds_each_controllers_calibrated_episodes() -> None:
    spec = parse_spec(SPEC, validate_env=False)
    calibrations = [
        estimate.Calibration("decoupled", 0.5, 10.0, 1.0),  # 0.5 + 1.0 / 10 = 0.6 s
        estimate.Calibration("unified", 1.0, 4.0, 1.0),  # 1.0 + 1.0 / 4 = 1.25 s
    ]
    todo = spec.episodes()[:10]  # 5 of each (controllers alternate)
    seconds, lines = estimate.from_calibration(spec, todo, calibrations, workers=2)
    assert seconds == pytest.approx((5 * 0.6 + 5 * 1.25) / 2)
    assert (
        "decoupled: setup 0.50 s, 10.0 x real time over 1 s -> 0.60 s per 1 s episode" in (lines[1])
    )


def test_calibration_measures_each_controller_on_the_specs_first_cell() -> None:
    spec = parse_spec(
        SPEC.replace("duration = 1.0", "duration = 0.2").replace(
            '"decoupled", "unified"', '"decoupled"'
        ),
        validate_env=False,
    )
    calls: list[tuple[Any, ...]] = []

    def episode(env, controller, parameters, seed, duration, preset=None, run_controllers=None):
        calls.append((controller, parameters, seed, duration))
        assert run_controllers == spec.controllers  # the overrides resolved for the whole run
        from benchmarks.rollout import run_configured_episode

        return run_configured_episode(
            env, controller, parameters, seed, duration, preset, run_controllers
        )

    (calibration,) = estimate.calibrate(spec, episode)
    first = spec.episodes()[0]
    assert [c[3] for c in calls] == [estimate.WARMUP_S, 0.2]  # capped at the spec's duration
    assert all(c[1] == first.parameters and c[2] == first.seed for c in calls)
    assert calibration.controller == "decoupled" and calibration.sim_time_s == pytest.approx(0.2)
    assert calibration.setup_s > 0 and calibration.real_time_factor > 0


def test_dry_run_estimates_from_a_calibration_on_the_specs_env(tmp_path: Path, capsys) -> None:
    path = tmp_path / "spec.toml"
    path.write_text(
        SPEC.replace('"decoupled", "unified"', '"decoupled"').replace(
            "duration = 1.0", "duration = 0.3"
        )
    )
    assert main(["sweep", str(path), "--dry-run", "--workers", "2"]) == 0
    text = capsys.readouterr().out
    assert "time estimate calibrated in this process" in text
    assert "  decoupled: setup " in text and "per 0.3 s episode, 128 episodes" in text
    assert "128 episodes to run on 2 workers: about" in text
    assert list(tmp_path.iterdir()) == [path]
