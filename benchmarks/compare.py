"""``wip-bench compare``: scenarios x controllers x seeds, a table, JSON and videos (issue 3).

Episode ``i`` of a run with ``--seed S`` uses seed ``S + i``. Episodes run in parallel in
spawned processes with ``--jobs`` (JAX does not survive a fork).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from benchmarks.episode import run_episode
from benchmarks.registry import controller_names
from benchmarks.render import VideoJobs, add_video_arguments, recording_file, video_options
from benchmarks.scenario import (
    DEFAULT_DURATION_S,
    Push,
    Scenario,
    check_task_flags,
    parse_controllers,
    resolve_env_id,
)

DEFAULT_ENV = "wip_gym/PlanarTray-v0"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", default=DEFAULT_ENV, help="env id (wip_gym/NAME or NAME)")
    parser.add_argument(
        "--controllers",
        default=",".join(controller_names()),
        help=f"comma-separated, from {controller_names()}",
    )
    parser.add_argument("--episodes", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--goal", type=float, nargs="+", metavar=("X", "Y"))
    parser.add_argument(
        "--push",
        help="NEWTONS@SECONDS[:DURATION] along the heading (a backward push: --push=-80@2)",
    )
    parser.add_argument("--payload", type=float, default=0.0, metavar="KG")
    parser.add_argument(
        "--payload-time",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="when the payload appears in the hand (0: from the start)",
    )
    parser.add_argument("--cup-friction", type=float, metavar="MU")
    parser.add_argument("--duration", type=float, default=DEFAULT_DURATION_S, metavar="SECONDS")
    parser.add_argument("--model", default="nominal", choices=["nominal", "oracle"])
    parser.add_argument("--jobs", type=int, default=1)
    add_video_arguments(parser, default_kind=None)  # --video [each|grid|both] of the 1st episode
    parser.add_argument("--out", default="out/compare")


def scenario_from_args(args: argparse.Namespace) -> tuple[Scenario, list[str]]:
    """Validate the flags; raise ValueError with the valid choices."""
    env_id = resolve_env_id(args.env)
    names = parse_controllers(args.controllers)
    if args.episodes < 1:
        raise ValueError(f"--episodes must be >= 1, got {args.episodes}")
    if args.jobs < 1:
        raise ValueError(f"--jobs must be >= 1, got {args.jobs}")
    check_task_flags(env_id, args.goal, args.cup_friction)
    for flag, value in (("--payload", args.payload), ("--payload-time", args.payload_time)):
        if not np.isfinite(value) or value < 0:
            raise ValueError(f"{flag} must be finite and >= 0, got {value}")
    scenario = Scenario(
        env_id=env_id,
        goal=tuple(args.goal) if args.goal is not None else None,
        push=Push.parse(args.push) if args.push else None,
        payload_mass=args.payload,
        payload_time=args.payload_time,
        cup_friction=args.cup_friction,
        duration=args.duration,
        model=args.model,
    )
    scenario.make_env().close()  # the env validates the task values (goal shape, ...)
    return scenario, names


def _stat(values: list[float | None], how: tuple[str, str] = ("mean", "max")) -> Any:
    present = [v for v in values if v is not None]
    if not present:
        return None
    funcs = {"mean": np.mean, "max": np.max, "p99": lambda v: np.percentile(v, 99)}
    return {k: float(funcs[k](present)) for k in how}


def _rate(values: list[bool | None]) -> float | None:
    present = [v for v in values if v is not None]
    return float(np.mean(present)) if present else None


def summarize(episodes: list[dict[str, Any]], control_times: list[np.ndarray]) -> dict[str, Any]:
    times = np.concatenate(control_times) * 1e3
    sim = sum(e["sim_time_s"] for e in episodes)
    wall = sum(e["sim_time_s"] / e["real_time_factor"] for e in episodes)
    return {
        "episodes": len(episodes),
        "success_rate": _rate([e["success"] for e in episodes]),
        "goal_reached_rate": _rate([e["goal_reached"] for e in episodes]),
        "cup_kept_rate": _rate([e["cup_kept"] for e in episodes]),
        "fell_rate": _rate([e["fell"] for e in episodes]),
        "time_to_goal_s": _stat([e["time_to_goal_s"] for e in episodes]),
        "final_goal_error_m": _stat([e["final_goal_error_m"] for e in episodes]),
        "max_tray_tilt_deg": _stat([e["max_tray_tilt_deg"] for e in episodes]),
        "max_ee_error_m": _stat([e["max_ee_error_m"] for e in episodes]),
        "max_cup_friction_use": _stat([e["max_cup_friction_use"] for e in episodes]),
        "control_time_ms": {"mean": float(times.mean()), "p99": float(np.percentile(times, 99))},
        "real_time_factor": float(sim / wall),
        "setup_s": float(np.mean([e["setup_s"] for e in episodes])),
    }


def _fmt(value: Any, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def format_table(summary: dict[str, Any]) -> str:
    header = (
        f"{'controller':<16}{'success':>8}{'goal':>6}{'cup':>6}{'fell':>6}"
        f"{'t_goal s':>10}{'err m':>8}{'tilt deg':>10}{'fric use':>10}"
        f"{'ctrl ms':>9}{'RTF':>7}"
    )
    lines = [f"{summary['env']}  ({json.dumps(summary['scenario'])})", header, "-" * len(header)]
    for name, s in summary["controllers"].items():

        def mean(key: str, s: dict[str, Any] = s) -> Any:
            return None if s[key] is None else s[key]["mean"]

        def peak(key: str, s: dict[str, Any] = s) -> Any:
            return None if s[key] is None else s[key]["max"]

        lines.append(
            f"{name:<16}{_fmt(s['success_rate'], '.2f'):>8}{_fmt(s['goal_reached_rate'], '.2f'):>6}"
            f"{_fmt(s['cup_kept_rate'], '.2f'):>6}{_fmt(s['fell_rate'], '.2f'):>6}"
            f"{_fmt(mean('time_to_goal_s'), '.2f'):>10}{_fmt(peak('final_goal_error_m'), '.3f'):>8}"
            f"{_fmt(peak('max_tray_tilt_deg'), '.2f'):>10}"
            f"{_fmt(peak('max_cup_friction_use'), '.2f'):>10}"
            f"{s['control_time_ms']['mean']:>9.3f}{s['real_time_factor']:>7.2f}"
        )
    return "\n".join(lines)


def run(args: argparse.Namespace) -> dict[str, Any]:
    scenario, names = scenario_from_args(args)
    env = scenario.make_env()
    videos = video_options(args, env.unwrapped.model)
    env.close()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tasks = []
    for name in names:
        for i in range(args.episodes):
            record = str(recording_file(out, name)) if (videos and i == 0) else None
            fps = videos.fps if videos else None
            tasks.append((scenario, name, args.seed + i, record, fps))
    # videos render from the recordings in another process while the next episodes run
    jobs = VideoJobs(out, videos, controllers=names) if videos else None
    results: list[dict[str, Any]] = [{} for _ in tasks]
    bar = tqdm(total=len(tasks), desc="episodes", unit="ep")

    def done(k: int, result: dict[str, Any]) -> None:
        results[k] = result
        bar.update()
        if jobs is not None and tasks[k][3] is not None:
            jobs.submit(tasks[k][1])

    if args.jobs == 1:
        for k, task in enumerate(tasks):
            done(k, run_episode(*task))
    else:
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=args.jobs, mp_context=context) as pool:
            futures = {pool.submit(run_episode, *task): k for k, task in enumerate(tasks)}
            for future in futures:
                done(futures[future], future.result())
    bar.close()
    episodes_done = time.perf_counter()
    with open(out / "episodes.jsonl", "w") as f:
        for r in results:
            f.write(json.dumps({k: v for k, v in r.items() if not k.startswith("_")}) + "\n")
    summary: dict[str, Any] = {
        "env": scenario.env_id,
        "scenario": scenario.describe(),
        "controllers": {},
    }
    summary["scenario"].update(episodes=args.episodes, seed=args.seed, controllers=names)
    for name in names:
        mine = [r for r in results if r["controller"] == name]
        summary["controllers"][name] = summarize(mine, [r["_control_times"] for r in mine])
    with open(out / "summary.json", "w") as f:
        json.dump(summary, f, indent=2)
    print(format_table(summary))
    print(f"\nwrote {out / 'summary.json'} and {out / 'episodes.jsonl'}")
    if jobs is not None:
        rendered = jobs.finish(names)
        for video in rendered["videos"]:
            print(f"video: {video}")
        print(
            f"videos: {rendered['render_process_s']:.1f} s of rendering, "
            f"{time.perf_counter() - episodes_done:.1f} s of it after the last episode"
        )
    return summary
