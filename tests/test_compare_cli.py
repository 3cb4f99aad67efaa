"""``wip-bench compare``: outputs, schema, flag validation, parallel determinism."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import pytest

from benchmarks.cli import main
from benchmarks.key_docs import MAX_LENGTH
from benchmarks.overrides import format_keys, resolve_run, valid_settings
from benchmarks.rollout import without_timing
from benchmarks.scenario import resolve_env_id
from controllers import registry

RATE_KEYS = {
    "success_rate",
    "carried_rate",
    "goal_reached_rate",
    "cup_kept_rate",
    "tray_kept_rate",
    "fell_rate",
}
METRIC_KEYS = {
    "time_to_goal_s",
    "final_goal_error_m",
    "max_tray_tilt_deg",
    "max_ee_error_m",
    "max_cup_friction_use",
    "cup_friction_use_p99",
    "slipping_time_s",
    "cup_slip_distance_m",
    "tray_slip_distance_m",
    "max_cup_tilt_deg",
    "cup_lost_at_s",
    "outcome_time_s",
    "time_at_actuator_limit_s",
    "sim_time_s",
    "real_time_factor",
    "setup_s",
}
SUMMARY_KEYS = (
    {"config", "episodes", "outcomes", "counters", "control_time_ms"} | RATE_KEYS | METRIC_KEYS
)
SPREAD = {"mean", "std", "min", "max", "n"}


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
        "--set",
        "env.reset_noise_scale=0.02",
    )
    assert summary["env"] == "wip_gym/PlanarTray-v0"
    assert summary["overrides"] == {"env.reset_noise_scale": 0.02} and summary["preset"] is None
    scenario = summary["scenario"]
    for key in (
        "goal",
        "cup_friction",
        "payload_mass",
        "push_force",
        "duration_s",
        "seed",
        "tray_attachment",
        "frame_skip",
        "terminate_on_cup_loss",
    ):
        assert key in scenario, key
    assert scenario["cup_friction"] == 0.3 and scenario["reset_noise_scale"] == 0.02
    assert scenario["seeds"] == [5, 6]
    stats = summary["controllers"]["decoupled"]
    assert set(stats) == SUMMARY_KEYS
    assert stats["episodes"] == 2
    assert stats["config"]["model"] == "nominal" and "plan" in stats["config"]
    for key in METRIC_KEYS - {"time_to_goal_s", "cup_lost_at_s", "outcome_time_s"}:
        assert set(stats[key]) == SPREAD and stats[key]["n"] == 2, key
        assert stats[key]["min"] <= stats[key]["mean"] <= stats[key]["max"], key
    for key in RATE_KEYS:
        assert stats[key]["n"] == 2 and stats[key]["ci95"][0] <= stats[key]["rate"], key
    assert set(stats["control_time_ms"]) == {"mean", "std", "min", "max", "p99"}
    assert all(set(v) == SPREAD for v in stats["counters"].values())
    assert stats["time_to_goal_s"] is None  # 0.3 s is too short to arrive
    lines = [json.loads(line) for line in (tmp_path / "episodes.jsonl").read_text().splitlines()]
    # the rates and the outcome counts are those of the episodes' lines
    assert [line["outcome"] for line in lines] == ["carried", "carried"]
    assert stats["outcomes"] == {"carried": 2} and stats["carried_rate"]["rate"] == 1.0
    assert stats["outcome_time_s"] is None  # no loss, no time
    assert [line["seed"] for line in lines] == [5, 6]
    # the summary's spread is that of the episodes' lines
    peaks = [line["max_cup_friction_use"] for line in lines]
    assert stats["max_cup_friction_use"]["min"] == min(peaks)
    assert stats["max_cup_friction_use"]["max"] == max(peaks)
    assert lines[0]["max_cup_friction_use"] != lines[1]["max_cup_friction_use"]  # seeds differ


def test_no_cup_metrics_are_null_without_a_tray(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    summary = run(
        tmp_path, "--env", "wip_gym/WIP-v0", "--controllers", "decoupled", "--duration", "0.2"
    )
    stats = summary["controllers"]["decoupled"]
    assert stats["cup_kept_rate"] is None and stats["max_cup_friction_use"] is None
    assert stats["carried_rate"] is None  # no tray: nothing to carry, not a rate of 0
    assert stats["outcomes"] == {"balanced": 1}
    table = capsys.readouterr().out
    assert "carried [95% CI]" in table and "outcomes (episodes): decoupled: balanced 1" in table


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
        return [without_timing(row) for row in rows]

    assert lines(tmp_path / "serial") == lines(tmp_path / "parallel")


def test_video_is_written(tmp_path: Path) -> None:
    run(tmp_path, "--env", "WIP-v0", "--controllers", "decoupled", "--duration", "0.2", "--video")
    assert (tmp_path / "video_decoupled.mp4").stat().st_size > 1000


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--set", "env.nope=1"], "env.nope"),
        (["--set", "env.cup_friction=abc"], "env.cup_friction"),
        (["--set", "plan.a_max=[1]"], "plan.a_max"),
        (["--set", "decoupled.nope=1"], "decoupled.nope"),
        (["--set", "unified.theta_kp=1"], "unified.theta_kp"),  # not in --controllers
        (["--set", "env.goal"], "KEY=VALUE"),
        (["--set", "env.goal=[1, 2]", "--env", "Planar-v0"], "goal"),  # the env rejects it
    ],
)
def test_bad_overrides_exit_2_naming_the_key_and_write_nothing(
    flags: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exit_info:
        main(["compare", "--out", str(out), "--controllers", "decoupled", *flags])
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_list_keys_prints_every_key_with_type_default_and_description(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    main(
        [
            "compare",
            "--env",
            "KrangTray-v0",
            "--controllers",
            "decoupled,unified",
            "--list-keys",
            "--out",
            str(out),
        ]
    )
    rows = {
        line.split()[0]: line.split(None, 1)[1] for line in capsys.readouterr().out.splitlines()
    }
    assert rows["env.cup_friction"].split()[:3] == ["float", "0.3", "tray-cup"]
    assert rows["env.goal"].split()[4:] == [
        "[2.0,",
        "0.0]",
        "goal",
        "x,",
        "or",
        "`(X,",
        "Y)`",
        "in",
        "3-D",
    ]
    assert rows["unified.ee_position_weight"].startswith("float")
    # each from where it is documented: the env's Arguments table, the config's Attributes
    assert rows["env.push_duration"].endswith("s the push lasts")
    assert "  how aggressive the plan may be, independent of the cup" in rows["plan.a_max"]
    assert rows["unified.high_level.mpc.ddp.second_order"].endswith(
        "True: DDP with the ``V_x . f_xx, f_ux, f_uu`` terms; False: iLQR (the authors' choice)."
    )
    for key in (
        "plan.a_max",
        "plan.q_position",
        "decoupled.posture_frequency_hz",
        "unified.theta_kp",
    ):
        assert key in rows, key
    assert not any(key.startswith("decoupled-mpc.") for key in rows)  # only these controllers
    assert not out.exists()


@pytest.mark.parametrize("env_id", ["WIP-v0", "PlanarTray-v0", "KrangTray-v0"])
def test_every_key_of_every_controller_has_a_one_line_description(env_id: str) -> None:
    spec = resolve_run(resolve_env_id(env_id), registry.controller_names())
    settings = valid_settings(spec.env_id, spec.configs)
    undocumented = [key for key, setting in settings.items() if not setting.description]
    assert not undocumented
    for setting in settings.values():
        assert "\n" not in setting.description and len(setting.description) <= MAX_LENGTH
    assert len(format_keys(settings).splitlines()) == len(settings)


def test_preset_paper_runs_and_records_its_settings(tmp_path: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # settings the preset cannot apply until env/ctrl land
        summary = run(
            tmp_path,
            "--env",
            "PlanarTray-v0",
            "--controllers",
            "decoupled",
            "--preset",
            "paper",
            "--duration",
            "0.3",
            "--cup-friction",
            "0.4",
        )
    scenario = summary["scenario"]
    assert summary["preset"] == "paper" and scenario["preset"] == "paper"
    assert scenario["goal"] == [5.0, 0.0]  # the preset's 5 m straight
    assert scenario["cup_friction"] == 0.4  # a named flag beats the preset
    if "tray_attachment" not in scenario.get("preset_skipped", []):
        assert scenario["tray_attachment"] == "free" and scenario["tray_rim"] == 0.005
    stats = summary["controllers"]["decoupled"]
    assert stats["episodes"] == 1 and stats["fell_rate"]["rate"] == 0.0
    assert stats["max_cup_friction_use"]["std"] == 0.0  # one episode: spread reported as 0
