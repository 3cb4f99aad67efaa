"""numba's on-disk cache, cleared when the compiled code's sources change.

numba caches a compiled function next to its source file (``__pycache__/*.nbi``, ``*.nbc``)
and keys the cache on that one file's contents. A compiled function that calls a compiled
function of another file has the callee compiled into its own machine code: the low level's
one-call step (``controllers.low_level.compiled_step``) holds the task rows, the motion probe
and the QP kernel of four other modules, the robot update holds ``wip_gym.small_linalg``'s
products. After an edit of a callee's file, the caller's cache still loads the old code, and
nothing says so (two benchmarks measured stale code: docs/performance.md §14 and
docs/performance.md §23).

:func:`drop_stale_caches` keeps one fingerprint of every source file of the packages with
compiled code (:data:`PACKAGES`) beside their caches and, when it differs from the sources',
deletes those packages' numba caches (what ``make clean-caches`` does by hand): everything
compiles again from the current sources, once. ``import wip_gym`` runs it, before anything
compiles or loads a cache (every module whose compiled functions call another module's imports
``wip_gym``).

Left alone: a cache directory of the user's choosing (``NUMBA_CACHE_DIR``; its layout is
numba's: clear it after an edit), and a source tree where the fingerprint cannot be written
(an installed, read-only package: its sources do not change). Concurrent processes of one tree
(a sweep's workers) may each clear the caches once after an edit; a process that finds a cache
file gone compiles again (numba's loader treats a missing file as no cache).
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Sequence
from pathlib import Path

#: the packages whose compiled functions call each other's (their sources are fingerprinted and
#: their caches cleared together)
PACKAGES = ("wip_gym", "controllers")

#: the repository (or site-packages) directory that holds :data:`PACKAGES`
ROOT = Path(__file__).resolve().parent.parent

#: the fingerprint's file name, in the first package's ``__pycache__``
STAMP = "numba-sources.sha256"


def source_fingerprint(root: Path, packages: Sequence[str]) -> str:
    """SHA-256 of every ``.py`` file under ``root / package`` (each file's path relative to
    ``root`` and its bytes, in sorted order)."""
    digest = hashlib.sha256()
    files = sorted(
        path
        for package in packages
        for path in (root / package).rglob("*.py")
        if "__pycache__" not in path.parts
    )
    for path in files:
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(b"\0")
        digest.update(path.read_bytes())
        digest.update(b"\0")
    return digest.hexdigest()


def drop_stale_caches(root: Path = ROOT, packages: Sequence[str] = PACKAGES) -> bool:
    """Delete the numba caches (``*.nbi``, ``*.nbc`` in every ``__pycache__``) of ``packages``
    under ``root`` if their sources changed since the fingerprint was last written, then write
    it; True if caches were cleared. Does nothing with ``NUMBA_CACHE_DIR`` set, or where the
    fingerprint cannot be written (module docstring)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return False
    stamp = root / packages[0] / "__pycache__" / STAMP
    fingerprint = source_fingerprint(root, packages)
    try:
        if stamp.read_text() == fingerprint:
            return False
    except OSError:
        pass  # no fingerprint yet: the caches, if any, are of unknown sources
    try:
        stamp.parent.mkdir(parents=True, exist_ok=True)
        for package in packages:
            for cache in (root / package).rglob("__pycache__"):
                for path in (*cache.glob("*.nbi"), *cache.glob("*.nbc")):
                    path.unlink(missing_ok=True)
        partial = stamp.with_name(f"{STAMP}.{os.getpid()}.tmp")
        partial.write_text(fingerprint)
        os.replace(partial, stamp)  # atomic: another process reads the old or the new one
    except OSError:
        return False  # a read-only tree: its sources do not change either
    return True
