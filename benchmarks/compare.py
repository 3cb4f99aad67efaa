"""``wip-bench compare``: scenarios x controllers x seeds, a table, JSON and videos.

Episode ``i`` of a run with ``--seed S`` uses ``benchmarks.seeding.episode_seed(S, i)`` (= S + i).
Episodes run in parallel in spawned processes with ``--jobs`` (JAX does not survive a fork).
Settings resolve in the order defaults, ``--preset``, named flags, ``--set`` (see
``benchmarks.overrides``; ``--list-keys`` prints every key). Two progress bars: episodes, and
the simulated seconds of all episodes (it moves inside a long episode).

A ``plan.*`` key applies to every controller with an offline plan and leaves the others as
they are (``benchmarks.overrides.keys_not_applied``, the sweep's rule too): the run prints a
note and ``summary.json`` lists them under ``keys_not_applied``. ``--import MODULE`` modules
are imported by the workers too.

Outputs in ``--out``: ``episodes.jsonl`` (one line per episode: ``benchmarks.metrics``, the
controller's ``counters``, timing), with ``--record-transitions`` one Minari dataset per
controller of every episode's observations, actions, rewards, terminations and truncations
(``datasets/wip_gym/<env name>/<controller>-v0``, ``benchmarks.transitions``), and
``summary.json``:

    {"env", "preset", "overrides": {key: value}, "keys_not_applied": {key: [controller]},
     "scenario": {every env argument in effect, "env", "duration_s", "control_dt_s",
                  "episodes", "seed", "seeds", "controllers", "preset"},
     "controllers": {name: {"config": {...resolved config...}, "episodes": n,
                            "<flag>_rate": {"rate", "ci95": [low, high], "n"} | null,
                            "outcomes": {outcome: episodes},
                            "<metric>": {"mean", "std", "min", "max", "n"} | null,
                            "counters": {name: {"mean", "std", "min", "max", "n"}},
                            "control_time_ms": {"mean", "std", "min", "max", "p99"}}}}
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import queue
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from benchmarks.episode import compare_episode
from benchmarks.metrics import outcome_counts
from benchmarks.overrides import (
    RunSpec,
    config_dict,
    format_keys,
    parse_assignment,
    resolve_run,
    valid_settings,
)
from benchmarks.presets import add_configuration_arguments
from benchmarks.render import VideoJobs, add_video_arguments, recording_file, video_options
from benchmarks.scenario import (
    DEFAULT_DURATION_S,
    Push,
    check_task_flags,
    parse_controllers,
    resolve_env_id,
)
from benchmarks.seeding import episode_seed
from benchmarks.statistics import describe, rate
from benchmarks.transitions import episode_file, require_minari, write_datasets
from controllers import registry
from controllers.optimizer import jax_setup

DEFAULT_ENV = "wip_gym/PlanarTray-v0"
RATES = ("success", "carried", "goal_reached", "cup_kept", "tray_kept", "fell")
METRICS = (
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
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", default=DEFAULT_ENV, help="env id (wip_gym/NAME or NAME)")
    parser.add_argument(
        "--controllers",
        help="comma-separated registry names (default: every registered controller but the "
        f"learned ppo, which runs where it has a checkpoint: "
        f"{', '.join(registry.default_controller_names())}, and those of --import modules)",
    )
    parser.add_argument("--episodes", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    add_configuration_arguments(
        parser,
        set_help="env.<argument>, plan.<field> or <controller>.<field.path>; JSON value "
        "(repeatable; see --list-keys)",
    )
    parser.add_argument(
        "--list-keys",
        action="store_true",
        help="print every --set key: its type, default and what it means",
    )
    parser.add_argument("--goal", type=float, nargs="+", metavar=("X", "Y"))
    parser.add_argument(
        "--push",
        help="NEWTONS@SECONDS[:DURATION] along the heading (a backward push: --push=-80@2)",
    )
    parser.add_argument("--payload", type=float, metavar="KG", help="env.payload_mass")
    parser.add_argument(
        "--payload-time",
        type=float,
        metavar="SECONDS",
        help="when the payload appears in the hand (0: from the start)",
    )
    parser.add_argument("--cup-friction", type=float, metavar="MU")
    parser.add_argument("--duration", type=float, default=DEFAULT_DURATION_S, metavar="SECONDS")
    parser.add_argument(
        "--model", choices=["nominal", "oracle"], help="every controller's model (nominal)"
    )
    parser.add_argument("--jobs", type=int, default=1)
    add_video_arguments(parser, default_kind=None)  # --video [each|grid|both] of the 1st episode
    parser.add_argument(
        "--record-transitions",
        action="store_true",
        help="write every episode's observations, actions, rewards, terminations and "
        "truncations as a Minari dataset per controller (OUT/datasets; needs wip-gym[data])",
    )
    parser.add_argument("--out", default="out/compare")


def named_env_flags(args: argparse.Namespace) -> dict[str, Any]:
    """The env arguments the named flags set (only those given)."""
    flags: dict[str, Any] = {}
    if args.goal is not None:
        flags["goal"] = args.goal[0] if len(args.goal) == 1 else tuple(args.goal)
    if args.push:
        push = Push.parse(args.push)
        flags.update(push_force=push.force, push_time=push.time, push_duration=push.duration)
    if args.payload is not None:
        flags["payload_mass"] = args.payload
    if args.payload_time is not None:
        flags["payload_time"] = args.payload_time
    if args.cup_friction is not None:
        flags["cup_friction"] = args.cup_friction
    return flags


def controller_list(args: argparse.Namespace) -> list[str]:
    """``--controllers``, or every default controller (``--import`` modules' included; the
    learned ``ppo`` only by name, ``registry.default_controller_names``)."""
    if args.controllers is None:
        return registry.default_controller_names()
    return parse_controllers(args.controllers)


def spec_from_args(args: argparse.Namespace) -> RunSpec:
    """Validate the flags and resolve the run; raise ValueError naming the bad flag or key
    and the valid choices (nothing has run or been written yet)."""
    env_id = resolve_env_id(args.env)
    names = controller_list(args)
    if args.episodes < 1:
        raise ValueError(f"--episodes must be >= 1, got {args.episodes}")
    if args.jobs < 1:
        raise ValueError(f"--jobs must be >= 1, got {args.jobs}")
    if not (np.isfinite(args.duration) and args.duration > 0):
        raise ValueError(f"--duration must be positive, got {args.duration}")
    check_task_flags(env_id, args.goal, args.cup_friction)
    if getattr(args, "record_transitions", False):
        require_minari()
    for flag, value in (("--payload", args.payload), ("--payload-time", args.payload_time)):
        if value is not None and (not np.isfinite(value) or value < 0):
            raise ValueError(f"{flag} must be finite and >= 0, got {value}")
    overrides = dict(parse_assignment(text) for text in args.overrides)
    controller_flags = {"model": args.model} if args.model is not None else {}
    spec = resolve_run(
        env_id, names, args.preset, named_env_flags(args), controller_flags, overrides
    )
    gym.make(env_id, **spec.env_kwargs).close()  # the env validates the values (goal shape)
    return spec


def list_keys(args: argparse.Namespace) -> str:
    """``--list-keys``: every key of this env and these controllers (defaults after the
    preset)."""
    env_id = resolve_env_id(args.env)
    spec = resolve_run(env_id, controller_list(args), args.preset)
    return format_keys(valid_settings(env_id, spec.configs))


def scenario_record(spec: RunSpec, args: argparse.Namespace, seeds: list[int]) -> dict[str, Any]:
    """``summary["scenario"]``: every env argument in effect and the run's settings."""
    env = gym.make(spec.env_id, **spec.env_kwargs)
    base = env.unwrapped
    record = spec.env_arguments()
    record.update(
        env=spec.env_id,
        goal=[float(v) for v in base.goal],
        duration_s=args.duration,
        control_dt_s=float(base.dt),
        episodes=args.episodes,
        seed=args.seed,
        seeds=seeds,
        controllers=list(spec.configs),
        preset=spec.preset,
    )
    if spec.skipped:
        record["preset_skipped"] = list(spec.skipped)
    env.close()
    return record


def summarize(episodes: list[dict[str, Any]], control_times: list[np.ndarray]) -> dict[str, Any]:
    """Every metric over the episodes with its spread, every flag as a rate with its Wilson
    95 % interval, the episodes per outcome, the controller's counters, the control time over
    all steps."""
    times = np.concatenate(control_times) * 1e3
    summary: dict[str, Any] = {"episodes": len(episodes)}
    for flag in RATES:
        summary[f"{flag}_rate"] = rate([e.get(flag) for e in episodes])
    summary["outcomes"] = outcome_counts(episodes)
    for metric in METRICS:
        summary[metric] = describe([e.get(metric) for e in episodes])
    counter_names = sorted({k for e in episodes for k in e.get("counters", {})})
    summary["counters"] = {
        k: describe([e.get("counters", {}).get(k) for e in episodes]) for k in counter_names
    }
    summary["control_time_ms"] = {
        "mean": float(times.mean()),
        "std": float(times.std()),
        "min": float(times.min()),
        "max": float(times.max()),
        "p99": float(np.percentile(times, 99)),
    }
    return summary


def _fmt(value: Any, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def _rate_with_interval(stat: dict[str, Any] | None) -> str:
    """``0.80 [0.49,0.94]``: a rate and its Wilson 95 % interval; ``-`` when not reported."""
    if stat is None:
        return "-"
    low, high = stat["ci95"]
    return f"{stat['rate']:.2f} [{low:.2f},{high:.2f}]"


def format_table(summary: dict[str, Any]) -> str:
    header = (
        f"{'controller':<16}{'carried [95% CI]':>18}{'success':>8}{'goal':>6}{'cup':>6}"
        f"{'fell':>6}{'t_goal s':>10}{'err m':>8}{'tilt deg':>10}{'fric use':>10}{'slip s':>8}"
        f"{'slip cm':>9}{'ctrl ms':>9}{'RTF':>7}"
    )
    scenario = {k: summary["scenario"][k] for k in ("env", "goal", "duration_s", "preset")}
    lines = [
        f"{summary['env']}  {json.dumps(scenario)}  overrides {json.dumps(summary['overrides'])}",
        "(rates over episodes, carried with its Wilson 95 % interval; means over episodes; "
        "fric use: peak, mean over episodes)",
        header,
        "-" * len(header),
    ]
    for name, s in summary["controllers"].items():

        def mean(key: str, s: dict[str, Any] = s, scale: float = 1.0) -> Any:
            return None if s[key] is None else s[key]["mean"] * scale

        def share(key: str, s: dict[str, Any] = s) -> Any:
            return None if s[key] is None else s[key]["rate"]

        lines.append(
            f"{name:<16}{_rate_with_interval(s['carried_rate']):>18}"
            f"{_fmt(share('success_rate'), '.2f'):>8}"
            f"{_fmt(share('goal_reached_rate'), '.2f'):>6}"
            f"{_fmt(share('cup_kept_rate'), '.2f'):>6}{_fmt(share('fell_rate'), '.2f'):>6}"
            f"{_fmt(mean('time_to_goal_s'), '.2f'):>10}{_fmt(mean('final_goal_error_m'), '.3f'):>8}"
            f"{_fmt(mean('max_tray_tilt_deg'), '.2f'):>10}"
            f"{_fmt(mean('max_cup_friction_use'), '.2f'):>10}"
            f"{_fmt(mean('slipping_time_s'), '.3f'):>8}"
            f"{_fmt(mean('cup_slip_distance_m', scale=100.0), '.2f'):>9}"
            f"{s['control_time_ms']['mean']:>9.3f}{mean('real_time_factor'):>7.2f}"
        )
    outcomes = {
        name: ", ".join(f"{kind} {n}" for kind, n in s["outcomes"].items())
        for name, s in summary["controllers"].items()
    }
    lines += ["", "outcomes (episodes): " + "; ".join(f"{k}: {v}" for k, v in outcomes.items())]
    return "\n".join(lines)


class _SimulatedSeconds:
    """The bar of simulated seconds over all episodes, fed ``(task_index, seconds)`` (counted
    in whole milliseconds, shown in seconds)."""

    def __init__(self, tasks: int, duration: float) -> None:
        self.duration_ms = int(round(duration * 1e3))
        self.done_ms = [0] * tasks
        self.bar = tqdm(
            total=tasks * self.duration_ms,
            desc="simulated",
            unit="s",
            unit_scale=1e-3,
            bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} s "
            "[{elapsed}<{remaining}]",
            position=1,
            leave=False,
        )

    def __call__(self, report: tuple[int, float]) -> None:
        index, seconds = report
        now = min(self.duration_ms, int(round(seconds * 1e3)))
        if now > self.done_ms[index]:
            self.bar.update(now - self.done_ms[index])
            self.done_ms[index] = now

    def finish(self, index: int) -> None:
        """An episode ended (perhaps early: a fall, a lost cup): count its whole duration."""
        self((index, self.duration_ms * 1e-3))

    def close(self) -> None:
        self.bar.close()


def _start_worker(imports: tuple[str, ...]) -> None:
    """A spawned worker's start: the ``--import`` modules, whose controllers its episodes
    make, and JAX's persistent compilation cache (``jax_setup.use_compilation_cache``)."""
    registry.import_modules(imports)
    jax_setup.use_compilation_cache()


def _run_tasks(
    tasks: list[tuple[Any, ...]],
    jobs: int,
    duration: float,
    on_done: Any = None,
    imports: tuple[str, ...] = (),
) -> list[Any]:
    results: list[Any] = [None] * len(tasks)
    episodes_bar = tqdm(total=len(tasks), desc="episodes", unit="ep", position=0)
    simulated = _SimulatedSeconds(len(tasks), duration)
    try:
        if jobs == 1:
            for k, task in enumerate(tasks):
                results[k] = compare_episode(*task, progress=simulated)
                simulated.finish(k)
                episodes_bar.update()
                if on_done is not None:
                    on_done(k)
            return results
        context = multiprocessing.get_context("spawn")
        with context.Manager() as manager:
            reports = manager.Queue()
            with ProcessPoolExecutor(
                max_workers=jobs,
                mp_context=context,
                initializer=_start_worker,
                initargs=(imports,),
            ) as pool:
                futures = {
                    pool.submit(compare_episode, *task, progress=reports): k
                    for k, task in enumerate(tasks)
                }
                pending = set(futures)
                while pending:
                    done, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
                    while True:
                        try:
                            simulated(reports.get_nowait())
                        except queue.Empty:
                            break
                    for future in done:
                        k = futures[future]
                        results[k] = future.result()
                        simulated.finish(k)
                        episodes_bar.update()
                        if on_done is not None:
                            on_done(k)
        return results
    finally:
        simulated.close()
        episodes_bar.close()


def run(args: argparse.Namespace) -> dict[str, Any] | None:
    if args.list_keys:
        print(list_keys(args))
        return None
    spec = spec_from_args(args)
    names = list(spec.configs)
    for key, left in spec.not_applied.items():
        print(f"note: {key} leaves {', '.join(left)} as configured (no offline plan)")
    env = gym.make(spec.env_id, max_episode_steps=-1, **spec.env_kwargs)
    videos = video_options(args, env.unwrapped.model)
    env.close()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    seeds = [episode_seed(args.seed, i) for i in range(args.episodes)]
    tasks = []
    for name in names:
        for i, seed in enumerate(seeds):
            record = str(recording_file(out, name)) if (videos and i == 0) else None
            transitions = str(episode_file(out, name, i)) if args.record_transitions else None
            tasks.append(
                (
                    len(tasks),
                    spec.env_id,
                    spec.env_kwargs,
                    name,
                    spec.configs[name],
                    seed,
                    args.duration,
                    record,
                    videos.fps if videos else None,
                    transitions,
                )
            )
    # videos render from the recordings in another process while the next episodes run
    jobs = VideoJobs(out, videos, controllers=names) if videos else None

    def render_when_recorded(k: int) -> None:
        if jobs is not None and tasks[k][7] is not None:
            jobs.submit(tasks[k][3])

    imports = tuple(getattr(args, "imports", ()))
    outcomes = _run_tasks(
        tasks, args.jobs, args.duration, on_done=render_when_recorded, imports=imports
    )
    episodes_done = time.perf_counter()
    results = [metrics for metrics, _ in outcomes]
    with open(out / "episodes.jsonl", "w") as f:
        for r in results:
            f.write(json.dumps(r) + "\n")
    summary: dict[str, Any] = {
        "env": spec.env_id,
        "preset": spec.preset,
        "overrides": spec.overrides,
        "scenario": scenario_record(spec, args, seeds),
        "keys_not_applied": {key: list(left) for key, left in spec.not_applied.items()},
        "controllers": {},
    }
    for name in names:
        mine = [k for k, r in enumerate(results) if r["controller"] == name]
        stats = summarize([results[k] for k in mine], [outcomes[k][1] for k in mine])
        summary["controllers"][name] = {"config": config_dict(spec.configs[name]), **stats}
    if args.record_transitions:
        indices = {name: list(range(args.episodes)) for name in names}
        datasets = write_datasets(out, spec.env_id, spec.env_kwargs, indices)
        summary["datasets"] = {"root": str(out / "datasets"), "ids": datasets}
    with open(out / "summary.json", "w") as f:
        json.dump(summary, f, indent=2)
    print(format_table(summary))
    print(f"\nwrote {out / 'summary.json'} and {out / 'episodes.jsonl'}")
    if args.record_transitions:
        print(
            f"datasets (Minari; MINARI_DATASETS_PATH={out / 'datasets'}): "
            + ", ".join(summary["datasets"]["ids"].values())
        )
    if jobs is not None:
        rendered = jobs.finish(names)
        for video in rendered["videos"]:
            print(f"video: {video}")
        print(
            f"videos: {rendered['render_process_s']:.1f} s of rendering, "
            f"{time.perf_counter() - episodes_done:.1f} s of it after the last episode"
        )
    return summary
