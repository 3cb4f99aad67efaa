"""The JAX settings of the controllers' solvers, which need no call by the user
(docs/DESIGN.md §4):

* **float64**, scoped: the DDP (``controllers.optimizer.ddp``), the MPC
  (``controllers.high_level.mpc``, its numba backend's code generation included), the plan's
  checks and the baselines' JAX calls run inside :func:`float64` (``jax.enable_x64(True)``, a
  thread-local scope: the MPC's thread enters its own), whatever the process's global
  ``jax_enable_x64``. Their results are float64 arrays; the rest of the process keeps its own
  settings. DDP's convergence tests and the Riccati recursion need float64.
* **XLA:CPU's "small while loop" threshold**, raised (``xla_cpu_small_while_loop_byte_threshold``,
  a backend option passed through ``XLA_FLAGS``). Below it, XLA compiles a whole ``while``
  loop (a ``lax.scan``, the DDP's iteration loop) into one kernel instead of dispatching every
  operation of every step through its runtime; its default (a few kB of loop state) leaves
  every DDP loop out. XLA reads the option once, when JAX creates its CPU backend (the
  process's first JAX computation), so it cannot be scoped: ``import controllers`` adds it to
  ``XLA_FLAGS`` (:func:`add_loop_flag`) unless that backend already runs. Then the first DDP
  solver warns once (:func:`warn_if_loop_flag_missing`) with the cost, :data:`LOOP_FLAG_COST`
  (:func:`loop_flag_cost` measures it). A value the user put in ``XLA_FLAGS`` is kept;
  ``WIP_GYM_XLA_SMALL_LOOP_BYTES`` sets the threshold (0: XLA's default, no warning).
* **The persistent compilation cache** is the program's choice, not the package's: it is
  process-wide, JAX reads it at its first compilation, and it would cache the program's own
  functions too. :func:`use_compilation_cache` turns it on (``~/.cache/wip-gym/jax``, or
  ``WIP_GYM_JAX_CACHE``; empty: off); wip-bench, its workers and the test suite call it, so that
  a new process loads the compiled DDP instead of compiling it again. Without it each process
  compiles the plan and the MPC once: the README's closed-loop recipe's ``policy.reset`` took
  10.3 s without the cache and 2.8 s with it warm (one run each, this 2-core machine).

:func:`configure` is kept for older programs and for those that call the package's JAX
functions themselves (the WIPM's functions, a solver's raw ``jitted``): the cache and float64
for the whole process.
"""

from __future__ import annotations

import functools
import os
import sys
import warnings
from collections.abc import Callable
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any, TypeVar

__all__ = [
    "CACHE_ENV",
    "LOOP_FLAG_COST",
    "SMALL_LOOP_ENV",
    "add_loop_flag",
    "cache_dir",
    "configure",
    "float64",
    "in_float64",
    "loop_flag_cost",
    "use_compilation_cache",
    "warn_if_loop_flag_missing",
]

CACHE_ENV = "WIP_GYM_JAX_CACHE"
SMALL_LOOP_ENV = "WIP_GYM_XLA_SMALL_LOOP_BYTES"
SMALL_LOOP_OPTION = "xla_cpu_small_while_loop_byte_threshold"
EXTRA_OPTIONS = "--xla_backend_extra_options="
# 64 MB: the largest loop state of the DDP (N = 2000, 3-D) is ~3 MB
DEFAULT_SMALL_LOOP_BYTES = 64 * 2**20
#: what the DDP loses without the loop option: the offline plan's solve (planar WIPM, N = 2000,
#: 10 iterations, after compilation), best of 20 in each of two processes (:func:`loop_flag_cost`).
#: Nine runs on the 2-core machine, shared with other jobs (load 8 to 12), gave 9 to 39 ms with
#: it and 85 to 176 ms without; the figure is the best of each.
LOOP_FLAG_COST = "about 9x slower (the offline plan's solve: 85 ms instead of 9 ms)"

F = TypeVar("F", bound=Callable[..., Any])


# ---------------------------------------------------------------------------------- float64
def float64() -> AbstractContextManager[Any]:
    """The solvers' scope: ``jax.enable_x64(True)`` (thread-local), tracing, compilation and
    calls inside it in float64 whatever the process's global setting."""
    import jax

    return jax.enable_x64(True)  # type: ignore[no-any-return]


def in_float64(function: F) -> F:
    """``function`` called inside :func:`float64` (about 2 us a call)."""

    @functools.wraps(function)
    def scoped(*args: Any, **kwargs: Any) -> Any:
        with float64():
            return function(*args, **kwargs)

    return scoped  # type: ignore[return-value]


# ---------------------------------------------------------------------- XLA's loop option
def loop_option() -> str | None:
    """``option=bytes`` of XLA's loop threshold, None when switched off (0)."""
    threshold = int(os.environ.get(SMALL_LOOP_ENV, DEFAULT_SMALL_LOOP_BYTES))
    return f"{SMALL_LOOP_OPTION}={threshold}" if threshold > 0 else None


def with_loop_option(flags: str, option: str) -> str:
    """``flags`` (an ``XLA_FLAGS`` value) with ``option`` among its backend options: added to
    an ``--xla_backend_extra_options`` already there (a threshold the user set is kept), or as
    one of its own."""
    tokens = flags.split()
    for index, token in enumerate(tokens):
        if token.startswith(EXTRA_OPTIONS):
            if SMALL_LOOP_OPTION in token:
                return flags
            tokens[index] = f"{token},{option}"
            return " ".join(tokens)
    return " ".join([*tokens, f"{EXTRA_OPTIONS}{option}"])


def backend_started() -> bool:
    """Whether JAX has created its backends (read without importing JAX). JAX has no public
    test; its ``xla_bridge.backends_are_initialized`` is used, and an unknown layout counts as
    started (the first solver then warns rather than trust a flag that may be late)."""
    bridge = sys.modules.get("jax._src.xla_bridge")
    if bridge is None:
        return False  # JAX's bridge not even imported: no backend
    started = getattr(bridge, "backends_are_initialized", None)
    if callable(started):
        return bool(started())
    backends = getattr(bridge, "_backends", None)
    return True if backends is None else bool(backends)


# the option's fate in this process: "set" (added before JAX started), "kept" (already in
# XLA_FLAGS), "off" (WIP_GYM_XLA_SMALL_LOOP_BYTES=0) or "late" (JAX had started)
_loop_flag: str | None = None
_warned = False


def add_loop_flag() -> str:
    """Put XLA's loop option in ``XLA_FLAGS`` if JAX's backend has not started (``import
    controllers`` calls it); return what happened: ``set``, ``kept``, ``off`` or ``late``.
    Idempotent."""
    global _loop_flag
    if _loop_flag is not None:
        return _loop_flag
    option = loop_option()
    flags = os.environ.get("XLA_FLAGS", "")
    if option is None:
        _loop_flag = "off"
    elif SMALL_LOOP_OPTION in flags:
        _loop_flag = "kept"
    elif backend_started():
        _loop_flag = "late"
    else:
        os.environ["XLA_FLAGS"] = with_loop_option(flags, option)
        _loop_flag = "set"
    return _loop_flag


def warn_if_loop_flag_missing() -> None:
    """Warn once per process, naming the cost, if JAX's backend started without the loop
    option (the DDP solver calls it when it is built)."""
    global _warned
    if _warned or add_loop_flag() != "late":
        return
    _warned = True
    warnings.warn(
        f"JAX started before wip-gym's controllers were imported, so XLA's {SMALL_LOOP_OPTION} "
        f"is not in effect and the DDP's loops run {LOOP_FLAG_COST}; results are unchanged. "
        "Import controllers (or wip_gym's controllers) before JAX's first computation, or "
        f"start Python with XLA_FLAGS={EXTRA_OPTIONS}{loop_option()}",
        RuntimeWarning,
        stacklevel=3,
    )


# ------------------------------------------------------------- the persistent compilation cache
def cache_dir() -> Path | None:
    """The persistent compilation cache's directory, None if switched off."""
    value = os.environ.get(CACHE_ENV)
    if value is None:
        return Path.home() / ".cache" / "wip-gym" / "jax"
    return Path(value) if value else None


def use_compilation_cache() -> None:
    """Turn on JAX's persistent compilation cache in :func:`cache_dir` (every compilation
    cached) unless the program set a directory or ``WIP_GYM_JAX_CACHE`` is empty. Call it
    before JAX compiles anything (idempotent)."""
    import jax

    directory = cache_dir()
    if directory is not None and jax.config.jax_compilation_cache_dir is None:
        directory.mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", str(directory))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


def configure() -> None:
    """For older programs and for those that call the package's JAX functions themselves:
    :func:`use_compilation_cache`, XLA's loop option if JAX has not started, and float64 for
    the whole process (``jax_enable_x64``). The solvers need none of it (idempotent)."""
    import jax

    add_loop_flag()
    jax.config.update("jax_enable_x64", True)
    use_compilation_cache()


def _best_plan_solve(threshold: int | None, repetitions: int) -> float:
    """Best of ``repetitions`` offline plans (planar, ``PlanarTray-v0``'s robot, after the
    compiling one) in a new process with the loop option at ``threshold`` bytes (None: the
    default), in seconds."""
    import subprocess

    env = dict(os.environ)
    env.pop("XLA_FLAGS", None)
    if threshold is not None:
        env[SMALL_LOOP_ENV] = str(threshold)
    code = (
        "import time, gymnasium as gym, numpy as np, wip_gym\n"
        "from controllers.policy import make_robot\n"
        "from controllers.high_level.planning import plan_to_goal\n"
        "from controllers.simplified.wipm import params_from_lambda\n"
        "from controllers.simplified.wipm_problem import wipm_state\n"
        "env = gym.make('wip_gym/PlanarTray-v0'); obs, _ = env.reset(seed=0)\n"
        "robot = make_robot(env, 'nominal'); robot.update(obs['qpos'], obs['qvel'])\n"
        "args = (wipm_state(robot), params_from_lambda(robot.wipm_parameters()))\n"
        "plan = lambda: plan_to_goal(*args, np.array([2.0, 0.0]), planar=True)\n"
        "plan(); times = []\n"
        f"for _ in range({repetitions}):\n"
        "    t = time.perf_counter(); plan(); times.append(time.perf_counter() - t)\n"
        "print(min(times))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    return float(result.stdout.split()[-1])


def loop_flag_cost(repetitions: int = 20) -> tuple[float, float]:
    """The offline plan's solve with and without XLA's loop option, each the best of
    ``repetitions`` in its own process, in seconds; printed with their ratio
    (:data:`LOOP_FLAG_COST`: ``python -c "from controllers.optimizer.jax_setup import
    loop_flag_cost; loop_flag_cost()"``)."""
    with_option, without = _best_plan_solve(None, repetitions), _best_plan_solve(0, repetitions)
    print(
        f"offline plan, best of {repetitions}: {with_option * 1e3:.1f} ms with "
        f"{SMALL_LOOP_OPTION}, {without * 1e3:.1f} ms without: {without / with_option:.1f}x"
    )
    return with_option, without
