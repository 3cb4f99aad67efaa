"""One closed-loop episode of a controller on a scenario, and its metrics (README "Metrics")."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.registry import make_policy
from benchmarks.scenario import Scenario
from wip_gym.recording import DEFAULT_FPS, EpisodeRecorder

GOAL_TOLERANCE_M = 0.05
STOP_SPEED_M_S = 0.05


def time_to_goal(t: np.ndarray, distance: np.ndarray, speed: np.ndarray) -> float | None:
    """The earliest time from which the robot stays within 5 cm of the goal and slower than
    5 cm/s until the episode's end; None if it never does."""
    ok = (distance < GOAL_TOLERANCE_M) & (speed < STOP_SPEED_M_S)
    if len(ok) == 0 or not ok[-1]:
        return None
    failures = np.flatnonzero(~ok)
    first = 0 if len(failures) == 0 else failures[-1] + 1
    return float(t[first])


def run_episode(
    scenario: Scenario,
    controller: str,
    seed: int,
    recording_path: str | Path | None = None,
    fps: float | None = None,
) -> dict[str, Any]:
    """Run one episode; return its metrics (JSON-ready) and the policy's per-step compute
    times under the private key ``_control_times``. With ``recording_path``, the episode is
    recorded at ``fps`` (default 30) for its video (``wip_gym.recording``; rendered afterwards)."""
    env = scenario.make_env()
    setup_start = time.perf_counter()
    observation, info = env.reset(seed=seed)
    policy = make_policy(controller, env, scenario.model)
    policy.reset(observation, info)
    setup_s = time.perf_counter() - setup_start

    dt = env.unwrapped.dt
    steps = int(round(scenario.duration / dt))
    recorder = None
    if recording_path is not None:
        rate = DEFAULT_FPS if fps is None else fps
        recorder = EpisodeRecorder(
            rate, controller, scenario.env_id, scenario.env_kwargs(), meta={"seed": seed}
        )
        recorder.on_reset(env, info)
    has_cup = "cup_on_tray" in info
    has_ee = "ee_error" in info
    times = np.zeros(steps)
    distance = np.zeros(steps)
    speed = np.zeros(steps)
    control_times = np.zeros(steps)
    fell = False
    cup_kept = True if has_cup else None
    max_tilt = info.get("tray_tilt_deg", 0.0) if has_cup else None
    max_ee = 0.0 if has_ee else None
    max_friction = 0.0 if has_cup else None
    loop_time = 0.0
    n = 0
    for n in range(steps):
        tick = time.perf_counter()
        action = policy(observation)
        tock = time.perf_counter()
        observation, _, terminated, truncated, info = env.step(action)
        loop_time += time.perf_counter() - tick
        control_times[n] = tock - tick
        times[n] = (n + 1) * dt
        distance[n] = info["goal_distance"]
        speed[n] = abs(info["xd"])
        fell = fell or info["fallen"]
        if has_cup:
            cup_kept = cup_kept and info["cup_on_tray"]
            max_tilt = max(max_tilt, info["tray_tilt_deg"])
            max_friction = max(max_friction, info["cup_friction_use"])
        if has_ee:
            max_ee = max(max_ee, info["ee_error"])
        if recorder is not None:
            recorder.on_step(env, info, n)
        if terminated or truncated:
            break
    if recorder is not None:
        recorder.save(recording_path)
    env.close()
    n_steps = n + 1
    reached_at = (
        None if fell else time_to_goal(times[:n_steps], distance[:n_steps], speed[:n_steps])
    )
    goal_reached = reached_at is not None
    result: dict[str, Any] = {
        "controller": controller,
        "seed": seed,
        "steps": n_steps,
        "sim_time_s": n_steps * dt,
        "fell": bool(fell),
        "goal_reached": goal_reached,
        "time_to_goal_s": reached_at,
        "final_goal_error_m": float(distance[n_steps - 1]),
        "cup_kept": cup_kept,
        "success": bool(goal_reached and not fell and cup_kept is not False),
        "max_tray_tilt_deg": max_tilt,
        "max_ee_error_m": max_ee,
        "max_cup_friction_use": max_friction,
        "control_time_ms_mean": float(control_times[:n_steps].mean() * 1e3),
        "control_time_ms_p99": float(np.percentile(control_times[:n_steps], 99) * 1e3),
        "real_time_factor": float(n_steps * dt / loop_time),
        "setup_s": setup_s,
        "_control_times": control_times[:n_steps],
    }
    return result
