"""``wip-bench profile`` (issue 6): runs, writes the documented JSON schema, and its parts add
up to the whole. No timing assertions (the figures depend on the machine)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from benchmarks.cli import main
from benchmarks.profile import ROWS

TOP_KEYS = {
    "env", "controller", "seed", "model", "duration_s", "steps", "control_dt_s", "frame_skip",
    "setup_s", "control_time_ms", "per_step_us", "qp_iterations", "qp_paths",
    "control_over_mujoco_step", "low_level_over_mujoco_step", "real_time_factor",
    "sim_only_real_time_factor", "fell", "machine",
}  # fmt: skip


def _mean(result: dict, name: str) -> float:
    return result["per_step_us"][name]["mean"]


def test_short_unified_profile_schema_and_sums(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "profile.json"
    argv = ["profile", "--env", "PlanarTray-v0", "--controller", "unified", "--duration", "0.3"]
    assert main([*argv, "--json", str(path)]) == 0
    printed = capsys.readouterr().out
    assert "| mujoco_step |" in printed and "real-time factor" in printed
    result = json.loads(path.read_text())
    assert set(result) == TOP_KEYS
    assert result["steps"] == 300 and result["env"] == "wip_gym/PlanarTray-v0"
    assert set(result["per_step_us"]) == set(ROWS)
    for name in ROWS:  # the unified controller has every part
        stats = result["per_step_us"][name]
        assert set(stats) == {"mean", "median"} and all(math.isfinite(v) for v in stats.values())
    for name in ("mujoco_step", "robot_model", "qp_assembly", "qp_solve", "high_level",
                 "control", "env_step"):  # fmt: skip
        assert _mean(result, name) > 0
    assert set(result["control_time_ms"]) == {"mean", "median", "p99"}
    assert result["control_time_ms"]["mean"] == pytest.approx(_mean(result, "control") / 1e3)
    parts = ("robot_model", "qp_assembly", "qp_solve", "high_level", "python_overhead")
    assert sum(_mean(result, p) for p in parts) == pytest.approx(_mean(result, "control"))
    # wrapped calls nest inside __call__: the rest is not negative beyond clock resolution
    assert _mean(result, "python_overhead") > -1.0
    assert _mean(result, "low_level") + _mean(result, "high_level") == pytest.approx(
        _mean(result, "control")
    )
    assert _mean(result, "mujoco_step") + _mean(result, "env_overhead") == pytest.approx(
        _mean(result, "env_step")
    )
    assert _mean(result, "control") + _mean(result, "env_step") == pytest.approx(
        _mean(result, "loop")
    )
    expected_rtf = result["steps"] * result["control_dt_s"] / (_mean(result, "loop") * 1e-6 * 300)
    assert result["real_time_factor"] == pytest.approx(expected_rtf)
    paths = result["qp_paths"]
    assert set(paths) == {"shortcut", "proxqp"} and paths["shortcut"] + paths["proxqp"] == 300
    assert result["qp_iterations"]["max"] >= 0
    assert result["setup_s"] > 0 and not result["fell"]


def test_profile_of_a_controller_without_a_task_qp(tmp_path: Path) -> None:
    path = tmp_path / "profile.json"
    argv = ["profile", "--env", "Planar-v0", "--controller", "decoupled", "--duration", "0.05"]
    assert main([*argv, "--json", str(path)]) == 0
    result = json.loads(path.read_text())
    assert set(result) == TOP_KEYS
    assert result["per_step_us"]["qp_assembly"] is None
    assert result["per_step_us"]["python_overhead"]["mean"] > 0


def test_unknown_controller_is_a_usage_error() -> None:
    with pytest.raises(SystemExit) as error:
        main(["profile", "--env", "PlanarTray-v0", "--controller", "nope"])
    assert error.value.code == 2
