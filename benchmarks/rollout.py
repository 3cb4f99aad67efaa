"""The one closed-loop rollout: every command, tool and closed-loop test runs episodes here, so
that every metric (``benchmarks.metrics``) is computed in one place.

    episode = rollout(env_id, env_kwargs, controller, config, seed, duration,
                      on_step=None, progress=None, keep_env=False)
    episode.metrics        # JSON-ready dict: benchmarks.metrics + counters, timing, identity
    episode.control_times  # (steps,) s per control step
    episode.policy         # the policy, after the episode (diagnostics, plan)
    episode.env            # the env, still open, with keep_env=True (close it yourself)

    row = run_configured_episode(env_id, controller, overrides, seed, duration, preset=None,
                                 run_controllers=None)

Seeds: episode ``i`` of a run with base seed ``S`` uses ``benchmarks.seeding.episode_seed(S, i)``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, SupportsFloat

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

import wip_gym  # noqa: F401  (registers the envs in a spawned worker)
from benchmarks.heap import setup_frozen
from benchmarks.metrics import EpisodeMetrics
from benchmarks.overrides import config_dict, parse_value, resolve_run
from benchmarks.scenario import resolve_env_id
from controllers import registry
from wip_gym.envs.base import wip_env

PROGRESS_INTERVAL_S = 0.1  # simulated seconds between progress callbacks
#: the fields of an episode's metrics that time the run rather than measure the episode (the
#: rest are the same on every run of the same seed on one machine)
TIMING_FIELDS = frozenset(
    {"control_time_ms_mean", "control_time_ms_p99", "real_time_factor", "setup_s"}
)


def without_timing(metrics: Mapping[str, Any]) -> dict[str, Any]:
    """An episode's metrics without :data:`TIMING_FIELDS`: what two runs of one seed share."""
    return {key: value for key, value in metrics.items() if key not in TIMING_FIELDS}


StepHook = Callable[[gym.Env, dict[str, Any], int], None]
ProgressHook = Callable[[float], None]


class TransitionHook(Protocol):
    """Sees the episode's stream (``benchmarks.transitions.TransitionRecorder``)."""

    def on_reset(self, observation: dict[str, Any]) -> None: ...

    def on_step(
        self,
        action: NDArray[Any],
        observation: dict[str, Any],
        reward: SupportsFloat,
        terminated: bool,
        truncated: bool,
    ) -> None: ...


class EpisodeError(RuntimeError):
    """An episode that raised while it ran (a controller's or the env's ValueError, e.g. a NaN
    action): a failure of the run, not of the command's arguments, so the CLI shows its
    traceback instead of a usage message."""


@dataclass
class Episode:
    """One rollout's outcome (see the module docstring)."""

    metrics: dict[str, Any]
    control_times: NDArray[np.float64]
    policy: Any
    env: gym.Env | None = None


def rollout(
    env_id: str,
    env_kwargs: Mapping[str, Any],
    controller: str,
    config: Any,
    seed: int,
    duration: float,
    on_step: StepHook | None = None,
    progress: ProgressHook | None = None,
    keep_env: bool = False,
    on_transition: TransitionHook | None = None,
) -> Episode:
    """Run ``controller`` (with its resolved ``config``) on ``gym.make(env_id, **env_kwargs)``
    reset with ``seed`` for ``duration`` simulated seconds, or until the env terminates.

    Args:
        env_kwargs: the env's arguments (rendering ones such as ``render_mode`` included).
        on_step: called as ``on_step(env, info, step_index)`` after the reset (index 0) and
            after every env step (index = steps taken), for recording or rendering.
        progress: called with the simulated time so far (s) every ``PROGRESS_INTERVAL_S``
            and at the end.
        keep_env: leave the env open and return it in ``Episode.env``.
        on_transition: given the reset's observation (``on_reset``) and each step's action,
            observation, reward, termination and truncation (``on_step``), to record them.
    """
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be positive, got {duration}")
    # no time limit (neither a TimeLimit nor the env's own 25 s) unless env_kwargs set one:
    # the duration ends the episode
    env = gym.make(env_id, max_episode_steps=-1, **{"time_limit": None, **env_kwargs})
    try:
        setup_start = time.perf_counter()
        observation, info = env.reset(seed=seed)
        policy = registry.make_policy(controller, env, config)
        policy.reset(observation, info)
        setup_s = time.perf_counter() - setup_start
        base = wip_env(env)
        dt = float(base.dt)
        low = np.asarray(base.action_space.low, dtype=np.float64)
        high = np.asarray(base.action_space.high, dtype=np.float64)
        metrics = EpisodeMetrics(dt, info, observation, low, high)
        if on_step is not None:
            on_step(env, info, 0)
        if on_transition is not None:
            on_transition.on_reset(observation)
        steps = int(round(duration / dt))
        report_every = max(1, int(round(PROGRESS_INTERVAL_S / dt)))
        loop_time = 0.0
        # no full collector pass over the setup's objects inside the loop (benchmarks.heap)
        with setup_frozen():
            for n in range(1, steps + 1):
                tick = time.perf_counter()
                try:
                    action = policy(observation)
                    tock = time.perf_counter()
                    observation, reward, terminated, truncated, info = env.step(action)
                except ValueError as error:  # not a usage error: say where the episode failed
                    raise EpisodeError(
                        f"{controller} on {env_id} (seed {seed}) failed at step {n} "
                        f"(t = {(n - 1) * dt:.3f} s): {error}"
                    ) from error
                loop_time += time.perf_counter() - tick
                metrics.update(info, observation, action, tock - tick)
                if on_transition is not None:
                    on_transition.on_step(action, observation, reward, terminated, truncated)
                if on_step is not None:
                    on_step(env, info, n)
                if progress is not None and n % report_every == 0:
                    progress(n * dt)
                if terminated or truncated:
                    break
        if progress is not None:
            progress(metrics.steps * dt)
        control_times = metrics.control_times
        result: dict[str, Any] = {"controller": controller, "seed": int(seed)}
        result.update(metrics.result())
        result["counters"] = {str(k): float(v) for k, v in policy.counters.items()}
        result.update(
            control_time_ms_mean=float(control_times.mean() * 1e3),
            control_time_ms_p99=float(np.percentile(control_times, 99) * 1e3),
            real_time_factor=float(metrics.steps * dt / loop_time),
            setup_s=setup_s,
        )
        return Episode(result, control_times, policy, env if keep_env else None)
    finally:
        if not keep_env:
            env.close()


def run_configured_episode(
    env_id: str,
    controller: str,
    overrides: Mapping[str, Any],
    seed: int,
    duration: float,
    preset: str | None = None,
    run_controllers: Sequence[str] | None = None,
) -> dict[str, Any]:
    """One episode of ``controller`` on ``env_id`` configured like ``wip-bench compare
    --preset PRESET --set KEY=VALUE ...``; its metrics row, JSON-ready.

    ``overrides`` maps ``--set`` keys (``benchmarks.overrides``) to values; a string value is
    parsed like a ``--set`` value (``"[2, 1]"`` is a list), other values are used as they are.
    ``run_controllers``: the controllers of the run the overrides were written for (a sweep's),
    ``controller`` among them; the overrides are resolved as compare resolves a run of them
    (so a ``plan.*`` key leaves a controller without an offline plan as it is, and is refused
    only if none of them has a plan), and this episode takes ``controller``'s config. Without
    it, the run is ``controller`` alone and keys of other registered controllers are ignored.
    The row: the rollout's metrics plus ``env``, ``preset``, ``overrides``, ``duration_s``,
    ``env_arguments`` (every env argument in effect) and ``config`` (the controller's resolved
    config).
    """
    env_id = resolve_env_id(env_id)
    parsed = {k: parse_value(v) if isinstance(v, str) else v for k, v in overrides.items()}
    if run_controllers is None:
        spec = resolve_run(
            env_id, [controller], preset, overrides=parsed, ignore_other_controllers=True
        )
    else:
        if controller not in run_controllers:
            raise ValueError(f"{controller!r} is not one of the run's {list(run_controllers)}")
        spec = resolve_run(env_id, run_controllers, preset, overrides=parsed)
    episode = rollout(env_id, spec.env_kwargs, controller, spec.configs[controller], seed, duration)
    row = dict(episode.metrics)
    row.update(
        env=env_id,
        preset=preset,
        overrides=spec.overrides,
        duration_s=float(duration),
        env_arguments=spec.env_arguments(),
        config=config_dict(spec.configs[controller]),
    )
    return row
