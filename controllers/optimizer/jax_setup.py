"""Process-wide JAX settings of the controllers' solvers, applied by ONE explicit call:
``controllers.optimizer.jax_setup.configure()``, before JAX starts (its first computation).
wip-gym's entry points make it (``wip-bench``, the sweep's workers, the test suite's
``conftest.py``, the tools); importing ``controllers`` changes nothing in the process. A program
that uses the controllers without it (or whose JAX already runs with other settings) gets one
warning from :func:`check`, when the first DDP solver is built, saying what it costs.

* float64 (``jax_enable_x64``): DDP's convergence tests and the Riccati recursion need it.
* XLA:CPU's "small while loop" threshold, raised (``xla_cpu_small_while_loop_byte_threshold``,
  an XLA backend option passed through ``XLA_FLAGS``). Below it, XLA compiles a whole
  ``while`` loop (a ``lax.scan``, the DDP's iteration loop) into one kernel instead of
  dispatching every operation of every step through its thunk runtime; measured on the DDP's
  backward pass (N = 2000, 2-core CPU) 0.2 us per step instead of 2-10 us. Its default (a few
  kB of loop state) leaves every DDP loop out. The option only takes effect if it is in
  ``XLA_FLAGS`` before JAX creates its CPU backend (the first JAX computation of the process);
  a value the user already put there is kept. ``WIP_GYM_XLA_SMALL_LOOP_BYTES`` overrides it (0
  leaves XLA's default).
* The persistent compilation cache (``jax_compilation_cache_dir``), so that a new process loads
  the compiled DDP instead of compiling it again (several seconds per problem and horizon):
  ``~/.cache/wip-gym/jax`` unless ``WIP_GYM_JAX_CACHE`` names another directory (an empty
  value switches it off). Every compilation is cached (no minimum compile time or entry size).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import jax
from jax._src import xla_bridge  # backends_are_initialized: no public equivalent

__all__ = ["CACHE_ENV", "SMALL_LOOP_ENV", "cache_dir", "check", "configure"]

CACHE_ENV = "WIP_GYM_JAX_CACHE"
SMALL_LOOP_ENV = "WIP_GYM_XLA_SMALL_LOOP_BYTES"
SMALL_LOOP_OPTION = "xla_cpu_small_while_loop_byte_threshold"
# 64 MB: the largest loop state of the DDP (N = 2000, 3-D) is ~3 MB
DEFAULT_SMALL_LOOP_BYTES = 64 * 2**20


def cache_dir() -> Path | None:
    """The persistent compilation cache's directory, None if switched off."""
    value = os.environ.get(CACHE_ENV)
    if value is None:
        return Path.home() / ".cache" / "wip-gym" / "jax"
    return Path(value) if value else None


def _small_loop_flag() -> str | None:
    threshold = int(os.environ.get(SMALL_LOOP_ENV, DEFAULT_SMALL_LOOP_BYTES))
    if threshold <= 0:
        return None
    return f"--xla_backend_extra_options={SMALL_LOOP_OPTION}={threshold}"


def _add_xla_flag() -> None:
    flags = os.environ.get("XLA_FLAGS", "")
    flag = _small_loop_flag()
    if flag is None or "xla_backend_extra_options" in flags:
        return  # the user's own backend options win
    if xla_bridge.backends_are_initialized():
        warnings.warn(
            "JAX's backend was initialised before jax_setup.configure() was called, so the DDP "
            f"runs without {SMALL_LOOP_OPTION} (correct, ~10x slower); call configure() before "
            f"JAX's first computation or set XLA_FLAGS={flag}",
            stacklevel=3,
        )
        return
    os.environ["XLA_FLAGS"] = f"{flags} {flag}".strip()


def configure() -> None:
    """Apply the settings above (idempotent)."""
    jax.config.update("jax_enable_x64", True)
    _add_xla_flag()
    directory = cache_dir()
    if directory is not None and jax.config.jax_compilation_cache_dir is None:
        directory.mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", str(directory))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


_checked = False


def missing_settings() -> list[str]:
    """What the running process lacks of the settings above, each with its cost."""
    missing = []
    if not jax.config.jax_enable_x64:
        missing.append(
            "float64 is off (jax_enable_x64): the DDP would run in float32, losing the "
            "precision its convergence tests and Riccati recursion need"
        )
    flag = _small_loop_flag()
    if flag is not None and SMALL_LOOP_OPTION not in os.environ.get("XLA_FLAGS", ""):
        missing.append(
            f"XLA's small-loop option is not set ({flag}): the DDP's loops run operation by "
            "operation, about 10x slower"
        )
    return missing


def check() -> None:
    """Warn once per process if the solver settings are missing (see :func:`missing_settings`);
    never changes JAX's configuration."""
    global _checked
    if _checked:
        return
    _checked = True
    missing = missing_settings()
    if missing:
        warnings.warn(
            "wip-gym's JAX settings are not applied: "
            + "; ".join(missing)
            + ". Call controllers.optimizer.jax_setup.configure() before JAX starts "
            "(wip-bench, the sweep's workers and the tests do).",
            RuntimeWarning,
            stacklevel=3,
        )
