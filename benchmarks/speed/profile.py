"""``wip-bench profile``: where the time of one closed-loop episode goes, per control step
against the simulator's own floor measured in the same run.

    wip-bench profile --env KrangTray-v0 --controller unified [--duration 5] [--seed 0]
                      [--preset paper] [--set KEY=VALUE ...] [--json PATH] [--no-freeze]
                      [--no-parts]

``--preset`` and ``--set`` are compare's (``benchmarks.overrides``): for example
``--set unified.high_level.mpc_delay_steps=5`` profiles the MPC solved beside the loop.

One episode of ``--duration`` s (the env's own task parameters, ``max_episode_steps`` off). The
timing definitions are the benchmark CLI's (``benchmarks.episode``): the control time is the
policy's ``__call__`` only; making the env, ``reset``, building the policy and its ``reset``
(compilation, the offline plan) count in ``setup_s``; the real-time factor is simulated time
over the time of ``policy(obs)`` plus ``env.step(action)`` summed over the steps.

The parts are timed with ``time.perf_counter`` around methods of the policy's own objects,
wrapped on the instance for this run only (the controller's code is not changed; a wrapper
costs well under a microsecond): ``robot.update`` (the robot model), ``qp._run_kernel`` (the
task rows, ``H``, ``g``, the constraint rows and the unconstrained minimiser, which both
``qp.assemble`` and ``qp.solve`` run) and ``qp.solve`` (the task QP; ``qp_solve`` is ``solve``
minus ``_run_kernel``) and
``high_level.reference`` (the MPC and the reference it hands the low level, amortised: it runs
every 10 ms), and the env's ``do_simulation`` (``env_physics``: its ``mj_step`` in the loop). A
part the controller lacks is ``null``. The part wrappers cost the control step itself about
0.1 to 0.15 units of its median (KrangTray-v0, ``unified``, five alternating pairs):
``--no-parts`` times the loop without them (every controller part and ``python_overhead``
``null``; the env's physics is still timed), for a control time comparable across controllers
whatever parts they have. The floor, ``mujoco_step``, is a bare
``mujoco.mj_step(model, data, nstep=frame_skip)`` (one control period) from every state the
episode stepped, with the control the policy gave there: the state (``mj_getState``, the
integration state) is recorded before every ``env.step`` and the floor is timed after the
episode, replaying them one by one on scratch data (the same states and model, in the same run;
the model as the episode left it, and an env push applied one step late, as the state before
``env.step`` holds it: neither moves the time of a step). Replayed back to back, these steps
find the caches warm; the loop's own ``mj_step`` (``env_physics``) does not, and costs 1.5 to
2.5 times as much.

Nothing runs between one step's ``env.step`` and the next ``policy(obs)`` but the profiler's
bookkeeping and, once every :data:`UNIT_EVERY` steps, a burst of the unit: measuring the floor
or the unit there at every step would evict the caches the loop works in and slow the steps
they precede. Measured on KrangTray-v0 with ``unified`` (8000 steps, blocks of 250 steps with
a floor and a reference step after every control step alternating with blocks without, three
runs): without them, the control step's median 0.74 to 0.82 times,
its mean 0.84 to 0.88 times, what it is with them.

The loop and the floor run with the setup's objects frozen (``benchmarks.heap.setup_frozen``):
a full pass of the garbage collector over them costs about 130 ms here, and fell inside some
8 s episodes and not others, adding about 2 units to a mean (``benchmarks.heap``). The
passes that remain in the loop are reported (``collector_passes``); ``--no-freeze`` times the
loop without the freeze.

The unit (``benchmarks.speed.yardstick``): ``reference_step_us``, the median of a bare, warm
``mj_step`` of Krang-v0's model at its reset state, timed in this process before and after the
episode and in bursts of :data:`UNIT_BURST` steps every :data:`UNIT_EVERY` control steps (so
that its samples see the machine's load as the episode's do; a burst perturbs the one control
step after it); ``per_step_units`` and ``control_time_units`` are the same figures divided by
it, so that they compare across machines and loads.

JSON schema (``--json PATH``; times per control step in microseconds unless named otherwise)::

    {
      "env": str, "controller": str, "seed": int, "model": "nominal",
      "preset": str | null, "overrides": {key: value},   # --preset, --set
      "duration_s": float, "steps": int, "control_dt_s": float, "frame_skip": int,
      "setup_s": float,                   # env reset + policy construction + policy.reset
      "reference_step_us": float,         # the unit (benchmarks.speed.yardstick)
      "control_time_ms": {"mean": float, "median": float, "p99": float},  # policy __call__
      "per_step_us": {                    # each {"mean": float, "median": float} or null
        "mujoco_step": ...,               # the floor: bare mj_step for one control period
        "robot_model": ...,               # RobotModel.update in the policy
        "qp_assembly": ...,               # TaskQP._run_kernel (tasks, Jdot nu, iso3, H, g, C, ...)
        "qp_solve": ...,                  # TaskQP.solve minus _run_kernel (ProxQP, copies)
        "high_level": ...,                # MPC + references (mean = amortised)
        "python_overhead": ...,           # control minus the four parts above
        "control": ...,                   # the policy's __call__
        "low_level": ...,                 # control minus high_level
        "env_step": ...,                  # env.step
        "env_physics": ...,               # the env's own mj_step calls in env.step
        "env_overhead": ...,              # env_step minus env_physics: the env's own work
        "loop": ...                       # control + env_step
      },
      "per_step_units": {...},            # per_step_us / reference_step_us, same keys
      "control_time_units": {"mean": float, "median": float, "p99": float},
      "qp_priority": "weighted" | "strict",
      "qp_iterations": {"mean": float, "max": int} | null,  # ProxQP's; 0 on a shortcut step
      "qp_paths": {"shortcut": int, "proxqp": int} | null,  # steps solved by each path
      "control_over_mujoco_step": float,  # mean control / mean floor
      "low_level_over_mujoco_step": float | null,  # null with --no-parts
      "real_time_factor": float,          # steps * dt / sum(control + env_step)
      "sim_only_real_time_factor": float, # steps * dt / sum(mujoco_step): the ceiling
      "fell": bool,
      "setup_frozen": bool,               # the loop under benchmarks.heap.setup_frozen
      "parts_timed": bool,                # the controller parts wrapped (not --no-parts)
      "collector_passes": {"by_generation": [int, int, int], "longest_ms": float,
                           "total_ms": float},  # the garbage collector's, in the loop
      "machine": {"cpu": str, "cores": int, "python": str}
    }

With the parts timed, the means of ``robot_model``, ``qp_assembly``, ``qp_solve``,
``high_level`` and ``python_overhead`` add up to the mean of ``control``, and ``low_level`` +
``high_level`` is ``control``; ``env_physics`` + ``env_overhead`` is ``env_step``; ``control``
+ ``env_step`` is ``loop`` (means). ``env_physics`` over ``mujoco_step`` is what the loop costs
the physics: the same steps, in the loop and warm.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from collections.abc import Callable
from contextlib import nullcontext
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from benchmarks.heap import CollectorPasses, setup_frozen
from benchmarks.overrides import parse_assignment, resolve_run
from benchmarks.presets import add_configuration_arguments
from benchmarks.scenario import resolve_env_id
from benchmarks.speed.yardstick import ReferenceStep, burst_due, reference_step_samples
from controllers.registry import controller_names, make_policy

PARTS = ("robot_model", "qp_assembly", "qp_solve", "high_level")
UNIT_EVERY = 250
"""Control steps between two bursts of the unit's reference step during an episode."""
UNIT_BURST = 20
"""Reference steps timed in one burst (after one untimed: ``ReferenceStep.burst``); with 400
before and 400 after the episode, an 8 s episode's unit has 1440 samples."""
STATE = mujoco.mjtState.mjSTATE_INTEGRATION
"""What the floor's replay restores before each step: everything ``mj_step`` reads."""
ROWS = (
    "mujoco_step",
    "robot_model",
    "qp_assembly",
    "qp_solve",
    "high_level",
    "python_overhead",
    "control",
    "low_level",
    "env_step",
    "env_physics",
    "env_overhead",
    "loop",
)


class _Timer:
    """Accumulates the time spent in wrapped calls during one control step."""

    def __init__(self) -> None:
        self.elapsed = 0.0

    def wrap(self, function: Callable[..., Any]) -> Callable[..., Any]:
        def timed(*args: Any, **kwargs: Any) -> Any:
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                self.elapsed += time.perf_counter() - start

        return timed

    def take(self) -> float:
        value, self.elapsed = self.elapsed, 0.0
        return value


def _instrument(policy: Any) -> dict[str, _Timer]:
    """Wrap the policy's parts that exist; return their timers."""
    timers: dict[str, _Timer] = {}
    robot = getattr(policy, "robot", None)
    if robot is not None and hasattr(robot, "update"):
        timers["robot_model"] = _Timer()
        robot.update = timers["robot_model"].wrap(robot.update)
    qp = getattr(policy, "qp", None)
    if qp is not None and hasattr(qp, "_run_kernel") and hasattr(qp, "solve"):
        timers["qp_assembly"] = _Timer()
        timers["qp_solve_total"] = _Timer()
        qp._run_kernel = timers["qp_assembly"].wrap(qp._run_kernel)
        qp.solve = timers["qp_solve_total"].wrap(qp.solve)
    high_level = getattr(policy, "high_level", None)
    if high_level is not None and hasattr(high_level, "reference"):
        timers["high_level"] = _Timer()
        high_level.reference = timers["high_level"].wrap(high_level.reference)
    return timers


def _stats(values: np.ndarray | None) -> dict[str, float] | None:
    if values is None:
        return None
    return {"mean": float(values.mean() * 1e6), "median": float(np.median(values) * 1e6)}


def _in_units(stats: dict[str, float] | None, unit_us: float) -> dict[str, float] | None:
    return None if stats is None else {key: value / unit_us for key, value in stats.items()}


def _iterations(iterations: np.ndarray | None) -> dict[str, float] | None:
    if iterations is None:
        return None
    return {"mean": float(np.mean(iterations)), "max": int(np.max(iterations))}


def _paths(iterations: np.ndarray | None) -> dict[str, int] | None:
    """Steps solved by the unconstrained shortcut (0 ProxQP iterations) and by ProxQP."""
    if iterations is None:
        return None
    return {"shortcut": int(np.sum(iterations == 0)), "proxqp": int(np.sum(iterations > 0))}


def replay_step(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    state: np.ndarray,
    action: np.ndarray,
    frame_skip: int,
) -> float:
    """Restore ``state`` (a row of :data:`STATE`) into ``data``, set the control ``action`` and
    time a bare ``mj_step(model, data, nstep=frame_skip)``; the wall time (s)."""
    mujoco.mj_setState(model, data, state, STATE)
    data.ctrl[:] = action
    start = time.perf_counter()
    mujoco.mj_step(model, data, nstep=frame_skip)
    return time.perf_counter() - start


def floor_times(
    model: mujoco.MjModel, states: np.ndarray, actions: np.ndarray, frame_skip: int
) -> np.ndarray:
    """The floor of the steps an episode took: :func:`replay_step` from each row of
    ``states`` (as ``mj_getState`` wrote them) with the same row of ``actions``, on scratch
    data, in order; wall times (s)."""
    size = mujoco.mj_stateSize(model, STATE)
    if states.ndim != 2 or states.shape[1] != size:
        raise ValueError(
            f"states must be rows of {size} (the integration state), got {states.shape}"
        )
    if actions.shape != (len(states), model.nu):
        raise ValueError(f"actions must be ({len(states)}, {model.nu}), got {actions.shape}")
    scratch = mujoco.MjData(model)
    return np.array(
        [
            replay_step(model, scratch, state, action, frame_skip)
            for state, action in zip(states, actions, strict=True)
        ]
    )


def make_env(env_id: str, env_kwargs: dict[str, Any]) -> gym.Env:
    """The profiled env: no time limit (the episode lasts ``--duration``)."""
    return gym.make(env_id, max_episode_steps=-1, **{"time_limit": None, **env_kwargs})


def profile_episode(
    env_id: str,
    controller: str,
    duration: float = 5.0,
    seed: int = 0,
    env_kwargs: dict[str, Any] | None = None,
    config: Any = None,
    freeze_setup: bool = True,
    time_parts: bool = True,
) -> dict[str, Any]:
    """Run one instrumented episode; return the JSON-ready profile (module docstring).
    ``env_kwargs`` and ``config`` (the controller's) default to the env's and the
    controller's defaults. ``freeze_setup=False`` times the loop without
    ``benchmarks.heap.setup_frozen`` (what a loop of one's own sees without it);
    ``time_parts=False`` without the controller parts' wrappers (``--no-parts``)."""
    if duration <= 0:
        raise ValueError(f"duration must be positive, got {duration}")
    env_id = resolve_env_id(env_id)
    reference_before = reference_step_samples()
    env = make_env(env_id, env_kwargs or {})
    setup_start = time.perf_counter()
    observation, info = env.reset(seed=seed)
    policy = make_policy(controller, env, config=config)
    policy.reset(observation, info)
    setup_s = time.perf_counter() - setup_start

    base = env.unwrapped
    model, data = base.model, base.data
    frame_skip = int(base.frame_skip)
    dt = float(base.dt)
    steps = int(round(duration / dt))
    if steps < 1:
        env.close()
        raise ValueError(f"duration {duration} s is less than one control step ({dt} s)")
    timers = _instrument(policy) if time_parts else {}
    physics_timer = _Timer()
    base.do_simulation = physics_timer.wrap(base.do_simulation)
    physics = np.zeros(steps)
    parts = {name: np.zeros(steps) for name in (*PARTS, "qp_solve_total")}
    control = np.zeros(steps)
    env_step = np.zeros(steps)
    states = np.zeros((steps, mujoco.mj_stateSize(model, STATE)))
    actions = np.zeros((steps, model.nu))
    reference_step = ReferenceStep()
    unit_samples: list[float] = []
    fell = False
    n = 0
    # the setup's objects out of the collector's full passes while the loop and its floor are
    # timed: such a pass (about 130 ms) landed inside some episodes and not others
    # (benchmarks.heap); the passes left in the loop are recorded
    with setup_frozen() if freeze_setup else nullcontext():
        with CollectorPasses() as collector:
            for n in range(steps):
                tick = time.perf_counter()
                action = policy(observation)
                tock = time.perf_counter()
                for name, timer in timers.items():
                    parts[name][n] = timer.take()
                mujoco.mj_getState(model, data, states[n], STATE)  # the floor's, timed after
                actions[n] = action
                start = time.perf_counter()
                observation, _, terminated, truncated, info = env.step(action)
                env_step[n] = time.perf_counter() - start
                physics[n] = physics_timer.take()
                control[n] = tock - tick
                if burst_due(n, UNIT_EVERY, steps):
                    unit_samples += reference_step.burst(UNIT_BURST)
                fell = fell or bool(info.get("fallen", False))
                if terminated or truncated:
                    break
        k = n + 1
        floor = floor_times(model, states[:k], actions[:k], frame_skip)
    env.close()
    reference = float(
        np.median(np.concatenate([reference_before, unit_samples, reference_step_samples()]))
    )
    control, env_step, physics = control[:k], env_step[:k], physics[:k]
    parts = {name: values[:k] for name, values in parts.items()}
    present = {name: name in timers for name in ("robot_model", "qp_assembly", "high_level")}
    present["qp_solve"] = "qp_solve_total" in timers
    parts["qp_solve"] = parts["qp_solve_total"] - parts["qp_assembly"]
    measured = sum(parts[name] for name in PARTS if present[name])
    high_level = parts["high_level"] if present["high_level"] else np.zeros(k)
    per_step: dict[str, dict[str, float] | None] = {
        "mujoco_step": _stats(floor),
        **{name: _stats(parts[name]) if present[name] else None for name in PARTS},
        "python_overhead": _stats(control - measured) if time_parts else None,
        "control": _stats(control),
        "low_level": _stats(control - high_level) if time_parts else None,
        "env_step": _stats(env_step),
        "env_physics": _stats(physics),
        "env_overhead": _stats(env_step - physics),
        "loop": _stats(control + env_step),
    }
    diagnostics = getattr(policy, "diagnostics", {})
    priority = getattr(policy.config, "priority", "weighted")
    # ProxQP's iterations: the weighted QP's (the strict stack solves its levels with DAQP)
    iterations = diagnostics.get("qp_iterations") if priority == "weighted" else None
    floor_mean = float(floor.mean())
    control_ms = {
        "mean": float(control.mean() * 1e3),
        "median": float(np.median(control) * 1e3),
        "p99": float(np.percentile(control, 99) * 1e3),
    }
    return {
        "env": env_id,
        "preset": None,
        "overrides": {},
        "controller": controller,
        "seed": seed,
        "model": getattr(policy.config, "model", "nominal"),
        "duration_s": duration,
        "steps": k,
        "control_dt_s": dt,
        "frame_skip": frame_skip,
        "setup_s": setup_s,
        "reference_step_us": reference * 1e6,
        "control_time_ms": control_ms,
        "per_step_us": per_step,
        "per_step_units": {
            name: _in_units(stats, reference * 1e6) for name, stats in per_step.items()
        },
        "control_time_units": {key: value * 1e-3 / reference for key, value in control_ms.items()},
        "qp_priority": priority,
        "qp_iterations": _iterations(iterations),
        "qp_paths": _paths(iterations),
        "control_over_mujoco_step": float(control.mean() / floor_mean),
        "low_level_over_mujoco_step": (
            float((control - high_level).mean() / floor_mean) if time_parts else None
        ),
        "real_time_factor": float(k * dt / (control.sum() + env_step.sum())),
        "sim_only_real_time_factor": float(k * dt / floor.sum()),
        "fell": fell,
        "setup_frozen": freeze_setup,
        "parts_timed": time_parts,
        "collector_passes": collector.summary(),
        "machine": {
            "cpu": platform.processor() or platform.machine(),
            "cores": os.cpu_count() or 0,
            "python": platform.python_version(),
        },
    }


def format_table(result: dict[str, Any]) -> str:
    per_step = result["per_step_us"]
    floor = per_step["mujoco_step"]["mean"]
    unit = result["reference_step_us"]
    lines = [
        f"{result['controller']} on {result['env']}: {result['steps']} steps of "
        f"{result['control_dt_s'] * 1e3:g} ms, seed {result['seed']}, setup "
        f"{result['setup_s']:.1f} s",
        f"unit: a bare mj_step of Krang-v0 at its reset state, {unit:.1f} us in this run",
        "",
        "| part (per control step) | mean us | median us | mean units | median units | x mj_step |",
        "|---|---|---|---|---|---|",
    ]
    for name in ROWS:
        stats = per_step[name]
        if stats is None:
            lines.append(f"| {name} | - | - | - | - | - |")
            continue
        lines.append(
            f"| {name} | {stats['mean']:.1f} | {stats['median']:.1f} | "
            f"{stats['mean'] / unit:.2f} | {stats['median'] / unit:.2f} | "
            f"{stats['mean'] / floor:.2f} |"
        )
    lines += [
        "",
        f"control time (policy __call__): mean {result['control_time_ms']['mean']:.3f} ms, "
        f"median {result['control_time_ms']['median']:.3f} ms, "
        f"p99 {result['control_time_ms']['p99']:.3f} ms "
        f"({result['control_time_units']['mean']:.1f} / "
        f"{result['control_time_units']['p99']:.1f} units mean / p99)",
        f"controller cost: {result['control_over_mujoco_step']:.1f}x the bare mj_step "
        + (
            f"(low level alone {result['low_level_over_mujoco_step']:.1f}x)"
            if result["low_level_over_mujoco_step"] is not None
            else "(parts not timed: --no-parts)"
        ),
        f"real-time factor: {result['real_time_factor']:.1f} (simulation alone "
        f"{result['sim_only_real_time_factor']:.1f})",
    ]
    passes = result["collector_passes"]
    frozen = "setup frozen" if result["setup_frozen"] else "setup not frozen: --no-freeze"
    lines.append(
        f"garbage collector in the loop ({frozen}): {sum(passes['by_generation'])} passes (by "
        f"generation {passes['by_generation']}), longest {passes['longest_ms']:.1f} ms"
    )
    if result.get("qp_priority") == "strict":
        lines.append("QP: strict priorities, DAQP's levels at every step")
    elif result["qp_iterations"] is not None:
        lines.append(
            f"QP: {result['qp_paths']['shortcut']} steps by the unconstrained shortcut, "
            f"{result['qp_paths']['proxqp']} by ProxQP (iterations: mean "
            f"{result['qp_iterations']['mean']:.2f}, max "
            f"{result['qp_iterations']['max']})"
        )
    return "\n".join(lines)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", required=True, help="env id, e.g. KrangTray-v0")
    parser.add_argument(
        "--controller", required=True, help=f"one of {', '.join(controller_names())}"
    )
    parser.add_argument("--duration", type=float, default=5.0, help="episode length (s)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", type=Path, default=None, help="write the profile here")
    parser.add_argument(
        "--no-parts",
        action="store_true",
        help="time the loop without the controller parts' wrappers (about 0.15 units of the "
        "control step): the parts and python_overhead are null",
    )
    parser.add_argument(
        "--no-freeze",
        action="store_true",
        help="time the loop without the setup's objects frozen (benchmarks.heap): a full "
        "garbage-collector pass may then fall inside it",
    )
    add_configuration_arguments(
        parser, set_help="env.<argument> or <controller>.<field.path>, as in compare (repeatable)"
    )


def run(args: argparse.Namespace) -> dict[str, Any]:
    if args.controller not in controller_names():
        raise ValueError(f"unknown controller {args.controller!r}; valid: {controller_names()}")
    env_id = resolve_env_id(args.env)
    overrides = dict(parse_assignment(text) for text in args.overrides)
    spec = resolve_run(env_id, [args.controller], args.preset, overrides=overrides)
    result = profile_episode(
        env_id,
        args.controller,
        args.duration,
        args.seed,
        spec.env_kwargs,
        spec.configs[args.controller],
        freeze_setup=not args.no_freeze,
        time_parts=not args.no_parts,
    )
    result["preset"] = args.preset
    result["overrides"] = spec.overrides
    print(format_table(result))
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2) + "\n")
    return result
