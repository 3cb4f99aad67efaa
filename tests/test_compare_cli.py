"""``wip-bench compare``: outputs, schema, flag validation, parallel determinism."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks.cli import main

SUMMARY_KEYS = {
    "episodes",
    "success_rate",
    "goal_reached_rate",
    "cup_kept_rate",
    "fell_rate",
    "time_to_goal_s",
    "final_goal_error_m",
    "max_tray_tilt_deg",
    "max_ee_error_m",
    "max_cup_friction_use",
    "control_time_ms",
    "real_time_factor",
    "setup_s",
}
TIMING_KEYS = {"control_time_ms_mean", "control_time_ms_p99", "real_time_factor", "setup_s"}


def run(tmp: Path, *flags: str) -> dict:
    main(["compare", "--out", str(tmp), *flags])
    return json.loads((tmp / "summary.json").read_text())


def test_summary_schema_and_episode_lines(tmp_path: Path) -> None:
    summary = run(
        tmp_path,
        "--env",
        "PlanarTray-v0",
        "--controllers",
        "decoupled",
        "--episodes",
        "2",
        "--duration",
        "0.3",
        "--seed",
        "5",
    )
    assert summary["env"] == "wip_gym/PlanarTray-v0"
    scenario = summary["scenario"]
    for key in ("goal", "cup_friction", "payload_mass", "push", "duration_s", "model", "seed"):
        assert key in scenario
    assert scenario["cup_friction"] == 0.3 and scenario["model"] == "nominal"
    stats = summary["controllers"]["decoupled"]
    assert set(stats) == SUMMARY_KEYS
    assert stats["episodes"] == 2
    assert set(stats["control_time_ms"]) == {"mean", "p99"}
    assert set(stats["max_tray_tilt_deg"]) == {"mean", "max"}
    assert stats["time_to_goal_s"] is None  # 0.3 s is too short to arrive
    lines = [json.loads(line) for line in (tmp_path / "episodes.jsonl").read_text().splitlines()]
    assert [line["seed"] for line in lines] == [5, 6]


def test_no_cup_metrics_are_null_without_a_tray(tmp_path: Path) -> None:
    summary = run(
        tmp_path, "--env", "wip_gym/WIP-v0", "--controllers", "decoupled", "--duration", "0.2"
    )
    stats = summary["controllers"]["decoupled"]
    assert stats["cup_kept_rate"] is None and stats["max_cup_friction_use"] is None


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--env", "Nope-v0"], "valid"),
        (["--controllers", "decoupled,nope"], "valid"),
        (["--push", "80at2"], "NEWTONS@SECONDS"),
        (["--episodes", "0"], "episodes"),
        (["--goal", "1", "2", "3"], "goal"),
        (["--env", "Planar-v0", "--goal", "1", "2"], "goal"),
        (["--env", "Planar-v0", "--cup-friction", "0.3"], "tray"),
        (["--payload", "-1"], "payload"),
    ],
)
def test_bad_flags_are_rejected_with_the_valid_values(
    flags: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["compare", "--out", str(tmp_path), "--duration", "0.1", *flags])
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err


def test_parallel_jobs_give_the_same_numbers(tmp_path: Path) -> None:
    flags = [
        "--env",
        "WIP-v0",
        "--controllers",
        "decoupled",
        "--episodes",
        "2",
        "--duration",
        "0.5",
        "--seed",
        "3",
    ]
    run(tmp_path / "serial", *flags, "--jobs", "1")
    run(tmp_path / "parallel", *flags, "--jobs", "2")

    def lines(folder: Path) -> list[dict]:
        rows = [json.loads(x) for x in (folder / "episodes.jsonl").read_text().splitlines()]
        return [{k: v for k, v in row.items() if k not in TIMING_KEYS} for row in rows]

    assert lines(tmp_path / "serial") == lines(tmp_path / "parallel")


def test_video_is_written(tmp_path: Path) -> None:
    run(tmp_path, "--env", "WIP-v0", "--controllers", "decoupled", "--duration", "0.2", "--video")
    assert (tmp_path / "video_decoupled.mp4").stat().st_size > 1000
