"""The sweep's spec, keys, seeds, statistics and report without Ray (``wip-bench sweep``)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from benchmarks.cli import main
from benchmarks.sweep.keys import validate_key
from benchmarks.sweep.report import write_report
from benchmarks.sweep.spec import SpecError, parse_spec
from benchmarks.sweep.stats import paired_success_difference, wilson_interval
from benchmarks.sweep.store import cut_torn_tail, read_rows

ISSUE_SPEC = """
env = "wip_gym/PlanarTray-v0"
controllers = ["unified", "decoupled-mpc"]
duration = 1.5
seeds = 2
seed = 7
[set]
"env.mass_randomization" = 0.05
[grid]
"env.cup_friction" = [0.2, 0.4]
"env.goal" = [1.0, 1.5]
[random]
"env.push_force" = { uniform = [-60.0, 60.0] }
[report]
axes = ["env.cup_friction", "env.goal"]
"""


def test_the_issue_spec_parses_into_its_cells_and_episodes():
    spec = parse_spec(ISSUE_SPEC)
    assert spec.env == "wip_gym/PlanarTray-v0"
    assert len(spec.cells()) == 4
    episodes = spec.episodes()
    assert len(episodes) == 4 * 2 * 2
    assert len({e.id for e in episodes}) == len(episodes)
    for e in episodes:
        assert e.parameters["env.mass_randomization"] == 0.05
        assert -60.0 <= e.parameters["env.push_force"] <= 60.0
    # every controller of a cell and replicate shares the seed and the random draws
    by_key: dict[tuple[int, int], set[tuple[int, float]]] = {}
    for e in episodes:
        by_key.setdefault((e.cell_index, e.replicate), set()).add(
            (e.seed, e.random["env.push_force"])
        )
    assert all(len(v) == 1 for v in by_key.values())
    assert len({next(iter(v))[0] for v in by_key.values()}) == len(by_key)


def test_seed_does_not_change_when_a_value_is_added_to_another_axis():
    before = parse_spec(ISSUE_SPEC, validate_env=False)
    after = parse_spec(
        ISSUE_SPEC.replace('"env.goal" = [1.0, 1.5]', '"env.goal" = [0.5, 1.0, 1.5]'),
        validate_env=False,
    )
    old = {
        (json.dumps(e.cell, sort_keys=True), e.replicate, e.controller): e
        for e in before.episodes()
    }
    new = {
        (json.dumps(e.cell, sort_keys=True), e.replicate, e.controller): e for e in after.episodes()
    }
    assert len(new) == len(old) * 3 // 2
    for key, episode in old.items():
        assert new[key].seed == episode.seed
        assert new[key].id == episode.id
        assert new[key].random == episode.random
    # the sweep's seed does change them
    reseeded = parse_spec(ISSUE_SPEC.replace("seed = 7", "seed = 8"), validate_env=False)
    assert {e.seed for e in reseeded.episodes()}.isdisjoint({e.seed for e in old.values()})


BAD_SPECS = {
    "unknown key": ('"env.mass_randomization" = 0.05', '"env.bogus_argument" = 0.05'),
    "empty axis": ('"env.goal" = [1.0, 1.5]', '"env.goal" = []'),
    "bad range": ("uniform = [-60.0, 60.0]", "uniform = [60.0, -60.0]"),
    "bad value": ('"env.cup_friction" = [0.2, 0.4]', '"env.cup_friction" = [0.2, -0.4]'),
    "bad kind": ('"env.cup_friction" = [0.2, 0.4]', '"env.cup_friction" = [0.2, "high"]'),
    "unknown controller": ('"decoupled-mpc"]', '"decoupled-mpcc"]'),
    "unknown top-level": ("seed = 7", "seed = 7\nseedz = 3"),
    "bad seeds": ("seeds = 2", "seeds = 0"),
    "unknown controller key": ("[set]", '[set]\n"decoupled.kp" = 1.0'),
    "report axis not in grid": (
        'axes = ["env.cup_friction", "env.goal"]',
        'axes = ["env.cup_friction", "env.push_force"]',
    ),
}
NAMED = {
    "unknown key": "env.bogus_argument",
    "empty axis": "env.goal",
    "bad range": "env.push_force",
    "bad value": "env.cup_friction",
    "bad kind": "env.cup_friction",
    "unknown controller": "decoupled-mpcc",
    "unknown top-level": "seedz",
    "bad seeds": "seeds",
    "unknown controller key": "decoupled.kp",
    "report axis not in grid": "env.push_force",
}


@pytest.mark.parametrize("case", sorted(BAD_SPECS))
def test_a_bad_spec_exits_2_names_the_problem_and_writes_nothing(case, tmp_path, capsys):
    old, new = BAD_SPECS[case]
    assert old in ISSUE_SPEC
    path = tmp_path / "spec.toml"
    path.write_text(ISSUE_SPEC.replace(old, new))
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exit_info:
        main(["sweep", str(path), "--out", str(out)])
    assert exit_info.value.code == 2
    assert NAMED[case] in capsys.readouterr().err
    assert not out.exists()


def test_dry_run_prints_cells_and_count(tmp_path, capsys):
    """Without calibration (the estimate: tests/test_sweep_frontier.py)."""
    path = tmp_path / "spec.toml"
    path.write_text(ISSUE_SPEC)
    assert main(["sweep", str(path), "--dry-run", "--workers", "2", "--no-calibration"]) == 0
    text = capsys.readouterr().out
    assert "4 cells x 2 controllers x 2 seeds = 16 episodes" in text
    assert "env.cup_friction=0.4, env.goal=1.5" in text
    assert "16 episodes to run on 2 workers (no time estimate" in text
    assert list(tmp_path.iterdir()) == [path]


def test_validate_key_reads_the_env_and_the_configs():
    env, controllers = "wip_gym/PlanarTray-v0", ["unified", "decoupled"]
    for key in (
        "env.mass_randomization",
        "env.cup_friction",
        "plan.a_max",
        "plan.ddp.max_iterations",
        "unified.ee_kp",
        "unified.high_level.mpc.horizon_s",
        "decoupled.plan.theta_max",
    ):
        validate_key(key, env, controllers)
    for key, named in (
        ("env.robot", "robot"),
        ("plan.bogus", "bogus"),
        ("unified.bogus", "bogus"),
        ("decoupled-mpc.kp_theta", "decoupled-mpc"),  # not one of the sweep's controllers
        ("cup_friction", "cup_friction"),
    ):
        with pytest.raises(ValueError, match=named):
            validate_key(key, env, controllers)


def test_plan_a_max_takes_the_cup_safe_cap_and_no_cap_as_words():
    spec = parse_spec(
        ISSUE_SPEC.replace(
            '"env.goal" = [1.0, 1.5]', '"plan.a_max" = ["cup_safe", 1.5, "none"]'
        ).replace('"env.goal"]', '"plan.a_max"]'),
        validate_env=False,
    )
    assert spec.grid["plan.a_max"] == ("cup_safe", 1.5, "none")
    with pytest.raises(SpecError, match="plan.a_max"):
        parse_spec(
            ISSUE_SPEC.replace('"env.goal" = [1.0, 1.5]', '"plan.a_max" = ["gentle"]').replace(
                '"env.goal"]', '"plan.a_max"]'
            ),
            validate_env=False,
        )


@pytest.mark.parametrize(
    ("successes", "n", "low", "high"),
    # Newcombe (1998), "Two-sided confidence intervals for the single proportion", Table I,
    # method 3 (the score interval)
    [
        (81, 263, 0.2553, 0.3662),
        (15, 148, 0.0624, 0.1605),
        (0, 20, 0.0, 0.1611),
        (1, 29, 0.0061, 0.1718),
    ],
)
def test_wilson_interval_matches_published_values(successes, n, low, high):
    interval = wilson_interval(successes, n)
    assert interval == pytest.approx((low, high), abs=6e-5)


def test_paired_success_difference_interval_behaves():
    # 10 of 10 against 0 of 10: clearly apart
    estimate, (low, high) = paired_success_difference([True] * 10, [False] * 10)
    assert estimate == 1.0
    assert 0.5 < low < high == 1.0
    # 8 discordant pairs against 2 (McNemar's exact p = 0.11): the interval includes 0
    a = [True] * 8 + [False] * 2
    b = [False] * 8 + [True] * 2
    estimate, (low, high) = paired_success_difference(a, b)
    assert estimate == pytest.approx(0.6)
    assert low < 0.0 < estimate < high < 1.0
    # swapping the controllers mirrors the interval
    mirrored, (m_low, m_high) = paired_success_difference(b, a)
    assert (mirrored, m_low, m_high) == pytest.approx((-0.6, -high, -low))
    # both succeed every time: zero, and an interval that narrows with more pairs
    _, wide = paired_success_difference([True] * 10, [True] * 10)
    _, narrow = paired_success_difference([True] * 100, [True] * 100)
    assert wide[0] < narrow[0] < 0.0 < narrow[1] < wide[1]
    assert math.isclose(wide[0], -wide[1])


def _row(identity: str, commit: str, status: str = "ok") -> dict:
    return {
        "id": identity,
        "status": status,
        "git_commit": commit,
        "git_dirty": False,
        "package_version": "0.1.0",
        "replicate": 0,
        "metrics": {"success": True, "max_cup_friction_use": 0.5},
    }


def test_the_report_says_when_commits_are_mixed_and_survives_a_torn_line(tmp_path):
    spec = parse_spec(ISSUE_SPEC, validate_env=False)
    episodes = spec.episodes()
    with open(tmp_path / "episodes.jsonl", "w") as f:
        f.write(json.dumps(_row(episodes[0].id, "aaa")) + "\n")
        f.write(json.dumps(_row(episodes[1].id, "bbb", "error")) + "\n")
        f.write(json.dumps(_row(episodes[1].id, "bbb")) + "\n")  # the rerun wins
        f.write('{"id": "torn", "sta')
    assert [r["id"] for r in read_rows(tmp_path)] == [episodes[0].id] + [episodes[1].id] * 2
    summary = write_report(spec, tmp_path)
    assert "rows from more than one commit are mixed" in (tmp_path / "report.md").read_text()
    for metric in ("success_rate", "max_cup_friction_use"):
        assert (tmp_path / f"heatmap_{metric}.png").stat().st_size > 0
    assert summary["mixed_commits"] is True
    assert summary["commits"] == ["aaa", "bbb"]
    assert summary["episodes_ok"] == 2
    assert summary["episodes_failed"] == 0
    assert summary["episodes_missing"] == len(episodes) - 2
    assert cut_torn_tail(tmp_path) == len('{"id": "torn", "sta')
    assert Path(tmp_path / "episodes.jsonl").read_text().endswith("\n")


def test_episodes_run_replicate_by_replicate_so_a_partial_sweep_is_balanced():
    spec = parse_spec(ISSUE_SPEC, validate_env=False)
    episodes = spec.episodes()
    per_replicate = len(spec.cells()) * len(spec.controllers)
    first = episodes[:per_replicate]
    assert {e.replicate for e in first} == {0}
    assert {e.cell_index for e in first} == set(range(len(spec.cells())))
    assert [e.replicate for e in episodes] == sorted(e.replicate for e in episodes)
    assert len({e.id for e in episodes}) == len(episodes) == per_replicate * spec.seeds


def test_a_one_axis_sweep_whose_cells_all_succeed_gets_its_line_plot(tmp_path):
    """Every episode a success: the Wilson interval's upper end is 1 up to round-off, and the
    error bars must not turn negative."""
    one_axis = (
        ISSUE_SPEC.replace("seeds = 2", "seeds = 10")
        .replace('"env.goal" = [1.0, 1.5]\n', "")
        .replace('axes = ["env.cup_friction", "env.goal"]', 'axes = ["env.cup_friction"]')
    )
    spec = parse_spec(one_axis, validate_env=False)
    with open(tmp_path / "episodes.jsonl", "w") as f:
        for episode in spec.episodes():
            f.write(json.dumps({**_row(episode.id, "aaa"), "replicate": episode.replicate}) + "\n")
    summary = write_report(spec, tmp_path)
    assert summary["episodes_ok"] == len(spec.episodes())
    assert (tmp_path / "line_env.cup_friction.png").stat().st_size > 0


def test_the_wilson_interval_ends_exactly_at_0_and_1_when_every_episode_agrees():
    from benchmarks.sweep.stats import wilson_interval

    for n in (1, 3, 10, 29, 100):
        assert wilson_interval(n, n)[1] == 1.0 and wilson_interval(n, n)[0] < 1.0
        assert wilson_interval(0, n)[0] == 0.0 and wilson_interval(0, n)[1] > 0.0
