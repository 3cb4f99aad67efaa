"""numba's on-disk cache, keyed on every compiled source file of the packages, not one.

numba caches a compiled function beside its source file (or in ``NUMBA_CACHE_DIR``) and keys
the cache on that one file's contents. A compiled function that calls a compiled function of
another file has the callee compiled into its own machine code: the low level's one-call step
(``controllers.low_level.compiled_step``) holds the task rows, the motion probe and the QP
kernel of four other modules, the QP kernel holds ``wip_gym.small_linalg``'s products. After
an edit of a callee's file, the caller's cache still loads the old code, and nothing says so
(two of the project's benchmarks measured stale code that way before this module).

:func:`install` makes numba key the caches of :data:`PACKAGES`' files on one fingerprint of all
their compiled source files (every ``.py`` file that imports numba) besides the file's own
contents: numba's cache locators for those files are subclassed so that their source stamp is
the pair, and an edit of any compiled file makes every cache of the packages stale, which numba
then treats as no cache and overwrites. Nothing is deleted, so processes never race over
files; a process started before an edit keeps the fingerprint it started with, and the caches
it writes afterwards are stale for every later process. ``import wip_gym`` installs it, before
the compiled functions of every module that imports ``wip_gym`` are defined: every module
whose compiled functions call another module's does. Two modules of leaf functions do not
(``controllers.low_level.compiled_tasks``, ``controllers.optimizer.scalar_codegen``): imported
before ``wip_gym``, theirs keep numba's own key, which is safe for functions that call no
other file's (a process that imports them in the other order compiles them once more).

Not covered: a module-level constant of a file without compiled code that a compiled function
reads (numba freezes it into the machine code, and numba's own cache does not see it either):
after changing one, run ``make clean-caches``. A ``NUMBA_CACHE_LOCATOR_CLASSES`` setting
replaces numba's locators, and these with them.
"""

from __future__ import annotations

import hashlib
import os
import re
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

#: the packages whose compiled functions call each other's
PACKAGES = ("wip_gym", "controllers")

#: the directory that holds :data:`PACKAGES` (the repository, or site-packages)
ROOT = Path(__file__).resolve().parent.parent

#: (a package directory with a trailing separator, the fingerprint of its package set)
_FINGERPRINTS: list[tuple[str, str]] = []


#: a line that imports numba: what makes a source file a compiled one here
_IMPORTS_NUMBA = re.compile(rb"^\s*(?:import numba\b|from numba\b)", re.MULTILINE)


def source_fingerprint(root: Path, packages: Sequence[str]) -> str:
    """SHA-256 of the compiled source files under ``root / package`` (the ``.py`` files that
    import numba: each one's path relative to ``root`` and its bytes, in sorted order). Files
    that are not regular files or cannot be read (an editor's lock link, a file deleted
    meanwhile) are left out."""
    digest = hashlib.sha256()
    paths = sorted(
        path
        for package in packages
        for path in (root / package).rglob("*.py")
        if "__pycache__" not in path.parts
    )
    for path in paths:
        try:
            if not path.is_file():
                continue
            source = path.read_bytes()
        except OSError:
            continue
        if not _IMPORTS_NUMBA.search(source):
            continue
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(b"\0")
        digest.update(source)
        digest.update(b"\0")
    return digest.hexdigest()


def fingerprint_of(py_file: str) -> str | None:
    """The fingerprint that keys ``py_file``'s caches (None: not a file of an installed
    package set)."""
    path = os.path.realpath(py_file)  # the same file through a symbolic link too
    for prefix, fingerprint in _FINGERPRINTS:
        if path.startswith(prefix):
            return fingerprint
    return None


def _locators(caching: Any) -> list[Any] | None:
    """numba's locators with the fingerprint in their source stamp, for the packages' files
    only; None (and a warning) if this numba has not the classes they extend."""
    names = ("UserProvidedCacheLocator", "InTreeCacheLocator", "UserWideCacheLocator")
    impl = getattr(caching, "CacheImpl", None)
    if not all(hasattr(caching, name) for name in names) or not isinstance(
        getattr(impl, "_locator_classes", None), list
    ):
        warnings.warn(
            "this numba's cache locators are not the ones wip_gym.compiled_cache extends: "
            "after editing compiled code, run `make clean-caches`",
            stacklevel=3,
        )
        return None

    class Fingerprinted:
        """A locator for the files of a fingerprinted package set: the source stamp is the
        file's own and the set's fingerprint."""

        _py_file: str

        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> Any:
            if fingerprint_of(py_file) is None:
                return None
            return super().from_function(py_func, py_file)  # type: ignore[misc]

        def get_source_stamp(self) -> Any:
            own = super().get_source_stamp()  # type: ignore[misc]
            return (own, fingerprint_of(self._py_file))

    return [
        type(
            f"Fingerprinted{name}",
            (Fingerprinted, getattr(caching, name)),
            {"__module__": __name__},
        )
        for name in names
    ]


def install(root: Path = ROOT, packages: Sequence[str] = PACKAGES) -> bool:
    """Key the numba caches of ``packages`` under ``root`` on their fingerprint (module
    docstring), for the functions defined from now on; again for a package directory replaces
    its fingerprint. False if numba's locators could not be extended."""
    fingerprint = source_fingerprint(root, packages)
    for package in packages:
        prefix = os.path.join(os.path.realpath(root / package), "")
        _FINGERPRINTS[:] = [(p, f) for p, f in _FINGERPRINTS if p != prefix]
        _FINGERPRINTS.append((prefix, fingerprint))
    from numba.core import caching

    current = getattr(getattr(caching, "CacheImpl", None), "_locator_classes", None)
    if isinstance(current, list) and any(c.__module__ == __name__ for c in current):
        return True  # installed already: the new fingerprints are read by the same classes
    locators = _locators(caching)
    if locators is None or not isinstance(current, list):
        return False
    caching.CacheImpl._locator_classes = locators + current
    return True
