"""Controllers from outside the repository reach ``wip-bench`` and its workers: an installed
plug-in (the ``wip_gym.controllers`` entry-point group) and ``--import MODULE``, through
``compare`` (in process and in ``--jobs`` workers) and a sweep on its own Ray cluster
(docs/extending.md §2). The plug-in is a distribution written to a temporary directory (a
package and its ``*.dist-info`` with ``entry_points.txt``) and put on ``PYTHONPATH`` of the
commands, each run in a fresh process as a user would run it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest

from benchmarks.sweep.store import read_rows
from controllers import registry
from tests.plugin_package import write_plugin

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ["decoupled", "decoupled-lqr", "decoupled-mpc", "unified", "unified-waiter"]


@pytest.fixture(scope="module")
def plugin_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A directory holding the installed plug-in and, apart, the module for --import."""
    return write_plugin(tmp_path_factory.mktemp("site"))


def _bench(site: Path, *args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": f"{site}{os.pathsep}{ROOT}", "MUJOCO_GL": "egl"}
    return subprocess.run(
        [sys.executable, "-m", "benchmarks.cli", *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=timeout,
        cwd=site,
    )


def test_an_installed_plugin_and_an_imported_module_run_through_compare(
    plugin_path: Path, tmp_path: Path
) -> None:
    out = tmp_path / "compare"
    result = _bench(
        plugin_path,
        "compare",
        "--env",
        "PlanarTray-v0",
        "--controllers",
        "balance,balance-imported,decoupled",
        "--import",
        "my_imported_controllers",
        "--episodes",
        "2",
        "--jobs",
        "2",  # spawned workers: each finds the plug-in and imports the module itself
        "--duration",
        "0.2",
        "--set",
        "plan.a_max=0.5",
        "--set",
        "balance.kd=90",
        "--out",
        str(out),
    )
    assert result.returncode == 0, result.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    controllers = summary["controllers"]
    assert list(controllers) == ["balance", "balance-imported", "decoupled"]
    assert controllers["balance"]["config"] == {"model": "nominal", "kp": 400.0, "kd": 90.0}
    assert controllers["balance-imported"]["config"]["kp"] == 500.0
    assert controllers["decoupled"]["config"]["plan"]["a_max"] == 0.5
    # the plan key reaches the controller with a plan and leaves the others, and says so
    assert summary["keys_not_applied"] == {"plan.a_max": ["balance", "balance-imported"]}
    assert "plan.a_max leaves balance, balance-imported as configured" in result.stdout
    rows = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert sorted(r["controller"] for r in rows) == sorted(
        ["balance", "balance", "balance-imported", "balance-imported", "decoupled", "decoupled"]
    )
    assert all(r["steps"] == 200 for r in rows)


def test_without_the_import_the_name_is_unknown_before_anything_runs(
    plugin_path: Path, tmp_path: Path
) -> None:
    result = _bench(
        plugin_path,
        "compare",
        "--controllers",
        "balance-imported",
        "--duration",
        "0.1",
        "--out",
        str(tmp_path / "none"),
    )
    assert result.returncode == 2
    assert "unknown controllers ['balance-imported']" in result.stderr
    assert "balance" in result.stderr  # the plug-in's names are among the valid ones
    assert not (tmp_path / "none").exists()
    missing = _bench(plugin_path, "compare", "--import", "no_such_module", "--list-keys")
    assert missing.returncode == 2
    assert "--import no_such_module: no module named 'no_such_module'" in missing.stderr


def test_profile_times_an_imported_controller(plugin_path: Path, tmp_path: Path) -> None:
    out = tmp_path / "profile.json"
    result = _bench(
        plugin_path,
        "profile",
        "--env",
        "PlanarTray-v0",
        "--controller",
        "balance-imported",
        "--import",
        "my_imported_controllers",
        "--duration",
        "0.1",
        "--json",
        str(out),
    )
    assert result.returncode == 0, result.stderr[-3000:]
    profile = json.loads(out.read_text())
    assert profile["controller"] == "balance-imported" and profile["steps"] == 100


SPEC = """
env = "PlanarTray-v0"
controllers = ["balance", "balance-imported", "broken", "decoupled"]
duration = 0.1
seeds = 1
[set]
"plan.a_max" = 0.5
[grid]
"balance.kd" = [70.0, 90.0]
"""


def test_a_sweep_runs_plugin_and_imported_controllers_and_exits_1_on_failed_episodes(
    plugin_path: Path, tmp_path: Path
) -> None:
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC)
    out = tmp_path / "sweep"
    common = ("--import", "my_imported_controllers")
    dry = _bench(plugin_path, "sweep", str(spec), "--dry-run", "--no-calibration", *common)
    assert dry.returncode == 0, dry.stderr[-3000:]
    assert "2 cells x 4 controllers x 1 seeds = 8 episodes" in dry.stdout
    assert "plan.a_max leaves balance, balance-imported, broken as configured" in dry.stdout

    run = _bench(plugin_path, "sweep", str(spec), "--out", str(out), "--workers", "2", *common)
    assert run.returncode == 1, run.stdout[-2000:] + run.stderr[-3000:]
    assert "2 episodes failed" in run.stdout
    rows = {(r["controller"], r["cell"]["balance.kd"]): r for r in read_rows(out)}
    assert len(rows) == 8
    for (controller, kd), row in rows.items():
        if controller == "broken":
            assert row["status"] == "error"
            assert "the plug-in's broken controller" in row["error"]
            continue
        assert row["status"] == "ok", row["error"]
        assert row["metrics"]["steps"] == 100
        config = row["metrics"]["config"]
        if controller == "balance":
            assert config["kd"] == kd
        elif controller == "balance-imported":
            assert (config["kp"], config["kd"]) == (500.0, 80.0)
        else:
            assert config["plan"]["a_max"] == 0.5
    # everything is written before the exit status says so
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["episodes_ok"], summary["episodes_failed"]) == (6, 2)
    assert summary["keys_not_applied"] == {"plan.a_max": ["balance", "balance-imported", "broken"]}
    report = (out / "report.md").read_text()
    assert "`plan.a_max` leaves balance, balance-imported, broken as configured" in report

    again = _bench(plugin_path, "sweep", "--report", str(out), *common)
    assert again.returncode == 0, again.stderr[-3000:]
    assert "6 ok, 2 failed" in again.stdout


# ------------------------------------------------------------------ loading, in this process
@pytest.fixture
def fresh_plugins(monkeypatch: pytest.MonkeyPatch):  # noqa: ANN201
    """The registry as before its plug-ins loaded, with ``entries`` as the installed group;
    every name registered meanwhile is removed afterwards."""
    before = dict(registry._REGISTRY)
    entries: list[metadata.EntryPoint] = []
    monkeypatch.setattr(registry, "_plugins", None)
    monkeypatch.setattr(
        registry.metadata,
        "entry_points",
        lambda group: [e for e in entries if e.group == group],
    )
    yield entries
    registry._REGISTRY.clear()
    registry._REGISTRY.update(before)


def test_an_entry_point_may_name_a_module_that_registers_on_import(
    fresh_plugins: list[metadata.EntryPoint], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "wipgym_module_plugin.py").write_text(
        "from controllers.registry import register\n"
        "register('module-toy', 'controllers.baselines.decoupled:DecoupledController',\n"
        "         'controllers.baselines.decoupled:DecoupledConfig', heading_gain_amps=1.0)\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    fresh_plugins.append(
        metadata.EntryPoint("toys", "wipgym_module_plugin", registry.ENTRY_POINT_GROUP)
    )
    fresh_plugins.append(metadata.EntryPoint("other", "os:getcwd", "another.group"))
    names = registry.controller_names()  # the first question loads the group
    assert names[-1] == "module-toy" and names[:5] == SHIPPED
    assert registry.default_config("module-toy").heading_gain_amps == 1.0
    assert registry.load_plugins() == []  # once per process


def test_an_entry_point_that_fails_is_named(fresh_plugins: list[metadata.EntryPoint]) -> None:
    fresh_plugins.append(
        metadata.EntryPoint("broken", "no_such_plugin_module:setup", registry.ENTRY_POINT_GROUP)
    )
    with pytest.raises(registry.PluginError, match="'broken = no_such_plugin_module:setup'"):
        registry.controller_names()
