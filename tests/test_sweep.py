"""``wip-bench sweep`` on a local Ray cluster shared by this module (2 CPUs): rows and summary,
resume, 1 against 2 workers, error rows, the workers' JAX settings, the episode runner's keys."""

from __future__ import annotations

import json
import os
import shutil
import signal
import threading
import time
from pathlib import Path

import pytest
import ray

from benchmarks.metrics import OUTCOMES
from benchmarks.rollout import run_configured_episode
from benchmarks.sweep import runner
from benchmarks.sweep.frontier import critical_value
from benchmarks.sweep.runner import RAY_TEMP_DIR, run_sweep
from benchmarks.sweep.spec import parse_spec
from benchmarks.sweep.store import read_rows

SPEC = """
env = "PlanarTray-v0"
controllers = ["decoupled", "unified"]
duration = 0.3
seeds = 2
seed = 3
[set]
"env.mass_randomization" = 0.05
[grid]
"env.cup_friction" = [0.2, 0.4]
[random]
"env.push_force" = { uniform = [-30.0, 30.0] }
[[frontier]]
axis = "env.cup_friction"
toward = "low"
rate = 0.5
"""
# Metrics that are physics, not wall-clock time: equal on any worker.
DETERMINISTIC = (
    "steps",
    "fell",
    "goal_reached",
    "cup_kept",
    "outcome",
    "outcome_time_s",
    "carried",
    "success",
    "final_goal_error_m",
    "max_tray_tilt_deg",
    "max_cup_friction_use",
    "max_ee_error_m",
)


@pytest.fixture(scope="module")
def cluster():
    os.environ["RAY_USAGE_STATS_ENABLED"] = "0"
    ray.init(
        address="local",
        num_cpus=2,
        include_dashboard=False,
        log_to_driver=False,
        _temp_dir=RAY_TEMP_DIR,
    )
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def small_sweep(cluster, tmp_path_factory):
    """The spec's 8 episodes on 2 workers."""
    directory = tmp_path_factory.mktemp("sweep") / "two_workers"
    summary = run_sweep(parse_spec(SPEC), directory, workers=2, progress=False)
    return directory, summary


def _by_id(directory: Path) -> dict[str, dict]:
    return {row["id"]: row for row in read_rows(directory)}


def test_a_small_sweep_writes_every_row_and_the_summary(small_sweep):
    directory, summary = small_sweep
    rows = read_rows(directory)
    spec = parse_spec(SPEC)
    assert sorted(r["id"] for r in rows) == sorted(e.id for e in spec.episodes())
    for row in rows:
        assert row["status"] == "ok", row["error"]
        assert row["error"] is None
        assert row["metrics"]["steps"] == 300
        assert row["parameters"]["env.mass_randomization"] == 0.05
        assert row["parameters"]["env.cup_friction"] == row["cell"]["env.cup_friction"]
        assert row["parameters"]["env.push_force"] == row["random"]["env.push_force"]
        assert row["wall_s"] > 0 and row["git_commit"] and row["package_version"]
    assert summary["engine"] == "ray"
    assert (summary["episodes_total"], summary["episodes_run"]) == (8, 8)
    assert (summary["episodes_skipped"], summary["episodes_failed"]) == (0, 0)
    assert [c["parameters"] for c in summary["cells"]] == [
        {"env.cup_friction": 0.2},
        {"env.cup_friction": 0.4},
    ]
    for cell in summary["cells"]:
        mine = [r for r in rows if r["cell"] == cell["parameters"]]
        for name, stats in cell["controllers"].items():
            peaks = [r["metrics"]["max_cup_friction_use"] for r in mine if r["controller"] == name]
            assert stats["n"] == 2
            assert stats["stats"]["max_cup_friction_use"]["max"] == max(peaks)
            low, high = stats["success_ci95"]
            assert low <= stats["success_rate"] <= high
            outcomes = [r["metrics"]["outcome"] for r in mine if r["controller"] == name]
            assert set(outcomes) <= set(OUTCOMES) and "balanced" not in outcomes
            assert stats["carried_rate"] == outcomes.count("carried") / 2
            low, high = stats["carried_ci95"]
            assert low <= stats["carried_rate"] <= high
            assert sum(stats["outcomes"].values()) == 2
        assert cell["paired"][0]["n"] == 2
    # the frontier: one row per controller (no other axis), from the cells' carried rates
    assert [r["controller"] for r in summary["frontier"]] == ["decoupled", "unified"]
    for row in summary["frontier"]:
        rates = [c["controllers"][row["controller"]]["carried_rate"] for c in summary["cells"]]
        assert row["rates"] == {"0.2": rates[0], "0.4": rates[1]} and row["fixed"] == {}
        assert row["critical"] == critical_value([0.4, 0.2], rates[::-1], 0.5)
    assert json.loads((directory / "summary.json").read_text())["episodes_total"] == 8
    report = (directory / "report.md").read_text()
    assert "| env.cup_friction=0.2 | decoupled | 2 |" in report and "## Frontiers" in report
    assert (directory / "line_env.cup_friction.png").stat().st_size > 0


def test_resume_runs_only_the_missing_rows(small_sweep, tmp_path):
    directory, _ = small_sweep
    copy = tmp_path / "resume"
    shutil.copytree(directory, copy)
    lines = (copy / "episodes.jsonl").read_text().splitlines(keepends=True)
    kept, deleted = lines[:5], lines[5:]
    # three rows lost, the last of them torn mid-write
    (copy / "episodes.jsonl").write_text("".join(kept) + deleted[0][:40])
    summary = run_sweep(parse_spec(SPEC), copy, workers=2, progress=False)
    assert (summary["episodes_run"], summary["episodes_skipped"]) == (3, 5)
    rows = read_rows(copy)
    assert len(rows) == 8 and len({r["id"] for r in rows}) == 8
    before = _by_id(directory)
    for row in rows:
        assert row["metrics"] == before[row["id"]]["metrics"] or row["id"] in {
            json.loads(line)["id"] for line in deleted
        }
    # a third run has nothing to do
    again = run_sweep(parse_spec(SPEC), copy, workers=2, progress=False)
    assert (again["episodes_run"], again["episodes_skipped"]) == (0, 8)
    assert len(read_rows(copy)) == 8


def test_one_and_two_workers_give_identical_metrics(small_sweep, tmp_path):
    directory, _ = small_sweep
    run_sweep(parse_spec(SPEC), tmp_path / "one", workers=1, progress=False)
    one, two = _by_id(tmp_path / "one"), _by_id(directory)
    assert one.keys() == two.keys()
    for identity, row in one.items():
        assert row["seed"] == two[identity]["seed"]
        for metric in DETERMINISTIC:
            assert row["metrics"][metric] == two[identity]["metrics"][metric], metric


def test_an_episode_that_raises_or_hangs_is_an_error_row_and_the_sweep_completes(cluster, tmp_path):
    spec = parse_spec(SPEC.replace("seeds = 2", "seeds = 1\ntimeout = 3"))

    def flaky(job):
        if job["controller"] == "unified" and job["cell"]["env.cup_friction"] == 0.4:
            raise RuntimeError("injected failure")
        if job["controller"] == "unified":
            time.sleep(30)  # outlives the 3 s limit
        return {"success": True, "max_cup_friction_use": 0.1}

    summary = run_sweep(spec, tmp_path, workers=2, episode_fn=flaky, progress=False)
    rows = {(r["controller"], r["cell"]["env.cup_friction"]): r for r in read_rows(tmp_path)}
    assert len(rows) == 4
    assert rows[("decoupled", 0.2)]["status"] == rows[("decoupled", 0.4)]["status"] == "ok"
    raised, hung = rows[("unified", 0.4)], rows[("unified", 0.2)]
    assert raised["status"] == "error" and raised["metrics"] is None
    assert "Traceback" in raised["error"] and "injected failure" in raised["error"]
    assert hung["status"] == "error" and "EpisodeTimeout" in hung["error"]
    assert hung["wall_s"] < 20
    assert summary["episodes_failed"] == 2 and summary["episodes_run"] == 4
    # a rerun retries only the error rows
    rerun = run_sweep(
        spec, tmp_path, workers=2, episode_fn=lambda job: {"success": False}, progress=False
    )
    assert (rerun["episodes_run"], rerun["episodes_skipped"], rerun["episodes_failed"]) == (2, 2, 0)


def test_workers_get_the_jax_settings_before_jax_starts(cluster, tmp_path):
    spec = parse_spec(SPEC.replace("seeds = 2", "seeds = 1").replace(', "unified"', ""))

    def report_settings(job):
        import jax

        return {
            "x64": bool(jax.config.jax_enable_x64),
            "xla_flags": os.environ.get("XLA_FLAGS"),
            "omp": os.environ.get("OMP_NUM_THREADS"),
            "openblas": os.environ.get("OPENBLAS_NUM_THREADS"),
            "cache": str(jax.config.jax_compilation_cache_dir),
        }

    run_sweep(spec, tmp_path, workers=2, episode_fn=report_settings, progress=False)
    for row in read_rows(tmp_path):
        m = row["metrics"]
        assert m["x64"] is False  # the solvers scope float64 themselves (tests/test_jax_setup.py)
        assert "xla_cpu_small_while_loop_byte_threshold" in m["xla_flags"]
        assert "--xla_cpu_multi_thread_eigen=false" in m["xla_flags"]
        assert m["omp"] == m["openblas"] == "1"
        assert m["cache"] != "None"


def test_the_episode_runner_applies_env_and_plan_keys_and_rejects_others():
    base = {"env.cup_friction": 0.3}
    plain = run_configured_episode("wip_gym/PlanarTray-v0", "decoupled", base, 5, 0.2)
    heavier = run_configured_episode(
        "wip_gym/PlanarTray-v0", "decoupled", {**base, "env.mass_randomization": 0.2}, 5, 0.2
    )
    gentle = run_configured_episode(
        "wip_gym/PlanarTray-v0", "decoupled", {**base, "plan.a_max": 0.2}, 5, 0.2
    )
    assert plain["steps"] == heavier["steps"] == 200
    assert heavier["max_ee_error_m"] != plain["max_ee_error_m"]
    assert gentle["max_ee_error_m"] != plain["max_ee_error_m"]
    for bad in ({"env.bogus": 1}, {"plan.bogus": 1}, {"decoupled.bogus": 1}, {"bogus": 1}):
        with pytest.raises(ValueError, match="bogus"):
            run_configured_episode("wip_gym/PlanarTray-v0", "decoupled", bad, 5, 0.2)


def test_ctrl_c_loses_only_the_episodes_in_flight(cluster, tmp_path):
    spec = parse_spec(SPEC.replace("seeds = 2", "seeds = 4"))  # 16 episodes

    def slow(job):
        time.sleep(1.0)
        return {"success": True, "max_cup_friction_use": 0.1}

    def interrupt_after_the_first_rows() -> None:
        # Ctrl-C once two episodes are stored, whatever the machine's load (a fixed delay
        # could fall before the sweep started or after it ended)
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline:
            if tmp_path.exists() and len(read_rows(tmp_path)) >= 2:
                break
            time.sleep(0.05)
        os.kill(os.getpid(), signal.SIGINT)

    timer = threading.Thread(target=interrupt_after_the_first_rows)
    timer.start()
    summary = run_sweep(spec, tmp_path, workers=2, episode_fn=slow, progress=False)
    timer.join()
    rows = read_rows(tmp_path)
    assert summary["interrupted"] is True
    assert 0 < len(rows) < 16
    assert all(r["status"] == "ok" for r in rows)
    assert summary["episodes_missing"] == 16 - len(rows)
    resumed = run_sweep(spec, tmp_path, workers=2, episode_fn=slow, progress=False)
    assert resumed["episodes_run"] == 16 - len(rows)
    assert len({r["id"] for r in read_rows(tmp_path)}) == len(read_rows(tmp_path)) == 16


def test_a_worker_that_dies_is_retried(cluster, tmp_path):
    spec = parse_spec(SPEC.replace("seeds = 2", "seeds = 1").replace(', "unified"', ""))
    marker = tmp_path / "died_once"

    def dies_once(job):
        if job["cell"]["env.cup_friction"] == 0.2 and not marker.exists():
            marker.touch()
            os._exit(1)  # the worker process dies mid-episode
        return {"success": True}

    summary = run_sweep(spec, tmp_path / "out", workers=2, episode_fn=dies_once, progress=False)
    assert marker.exists()
    assert summary["episodes_failed"] == 0 and summary["episodes_ok"] == 2
    assert len(read_rows(tmp_path / "out")) == 2


def test_an_episode_deaf_to_the_alarm_is_killed_by_the_driver(cluster, tmp_path, monkeypatch):
    monkeypatch.setattr(runner, "HARD_LIMIT_MARGIN_S", 2.0)  # hard limit 1.5 * 1 + 2 = 3.5 s
    spec = parse_spec(
        SPEC.replace("seeds = 2", "seeds = 1\ntimeout = 1").replace(', "unified"', "")
    )

    def stuck(job):
        if job["cell"]["env.cup_friction"] == 0.4:
            signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGALRM})  # like a long C call
            time.sleep(60)
        return {"success": True}

    start = time.monotonic()
    summary = run_sweep(spec, tmp_path, workers=2, episode_fn=stuck, progress=False)
    assert time.monotonic() - start < 30
    rows = {r["cell"]["env.cup_friction"]: r for r in read_rows(tmp_path)}
    assert rows[0.2]["status"] == "ok"
    assert rows[0.4]["status"] == "error" and "worker was killed" in rows[0.4]["error"]
    assert summary["episodes_failed"] == 1
