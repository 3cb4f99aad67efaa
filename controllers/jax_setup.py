"""Process-wide JAX settings of the controllers (issue 6), applied once at import of any module
that compiles JAX code (``controllers.ddp``, ``controllers.wipm``).

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

__all__ = ["CACHE_ENV", "SMALL_LOOP_ENV", "cache_dir", "configure"]

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
            "JAX's backend was initialised before controllers was imported, so the DDP runs "
            f"without {SMALL_LOOP_OPTION} (correct, ~10x slower); import controllers first or "
            f"set XLA_FLAGS={flag}",
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


configure()
