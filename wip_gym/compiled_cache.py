"""numba's on-disk cache in a directory keyed on the packages' compiled sources.

numba caches a compiled function keyed on its own source file. A compiled function that calls a
compiled function of another file has the callee compiled into its own machine code (the low
level's one-call step holds the task rows, the motion probe and the QP kernel of other modules),
and a module-level constant it reads is frozen into it: after an edit of the callee's file, or
of the file a constant comes from, the caller's cache still loads the old code, and nothing
says so.

:func:`configure` sets numba's public cache directory setting (``numba.config.CACHE_DIR``, the
value of ``NUMBA_CACHE_DIR``) to a directory named after :func:`source_fingerprint`: the
SHA-256 of every compiled source file of :data:`PACKAGES` (a ``.py`` file that imports numba)
and of every module of the packages they import, directly or through others (where their
constants come from). An edit of any of those files gives a new directory, so every cache of
the packages is compiled again from the current sources; nothing is deleted, so processes never
race over files. ``import wip_gym`` calls it before any compiled function of the packages is
defined (numba takes the directory when a function is defined).

The directory is ``<base>/<fingerprint>`` with ``<base>`` the user's own ``NUMBA_CACHE_DIR``
under ``wip-gym`` when one is set, else ``~/.cache/wip-gym/compiled`` (``make clean-caches``
deletes the old ones). It is numba's setting for the whole process: a cached function of
another library defined after ``import wip_gym`` is cached there too (compiled again when the
fingerprint changes). A process started before an edit keeps the directory it started with.
"""

from __future__ import annotations

import ast
import hashlib
import os
import re
from collections.abc import Iterable, Sequence
from pathlib import Path

#: the packages whose compiled functions call each other's
PACKAGES = ("wip_gym", "controllers")

#: the directory that holds :data:`PACKAGES` (the repository, or site-packages)
ROOT = Path(__file__).resolve().parent.parent

#: a line that imports numba: what makes a source file a compiled one here
_IMPORTS_NUMBA = re.compile(rb"^\s*(?:import numba\b|from numba\b)", re.MULTILINE)


def _read(path: Path) -> bytes | None:
    """The bytes of a regular file, None for anything else (an editor's lock link, a file
    deleted meanwhile)."""
    try:
        return path.read_bytes() if path.is_file() else None
    except OSError:
        return None


def _module_file(root: Path, packages: Sequence[str], name: str) -> Path | None:
    """The source file of the module ``name`` if it is one of ``packages``' (a package's
    ``__init__.py``), else None."""
    parts = name.split(".")
    if parts[0] not in packages:
        return None
    path = root.joinpath(*parts)
    for candidate in (path / "__init__.py", path.with_suffix(".py")):
        if candidate.is_file():
            return candidate
    return None


def _imported(root: Path, packages: Sequence[str], source: bytes) -> Iterable[Path]:
    """The packages' modules a source imports: ``import a.b`` gives ``a/b``; ``from a.b import
    c`` gives ``a/b/c`` when that is a module, else ``a/b`` (where the name lives)."""
    try:
        tree = ast.parse(source)
    except SyntaxError:
        return  # the process will fail on it anyway
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                found = _module_file(root, packages, alias.name)
                if found is not None:
                    yield found
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for alias in node.names:
                found = _module_file(root, packages, f"{node.module}.{alias.name}")
                if found is None:
                    found = _module_file(root, packages, node.module)
                if found is not None:
                    yield found


def fingerprinted_files(root: Path, packages: Sequence[str]) -> list[Path]:
    """The files :func:`source_fingerprint` covers, sorted: the compiled source files under
    ``root / package`` (the ``.py`` files that import numba) and the packages' modules they
    import, directly or through each other."""
    sources = {
        path: _read(path)
        for package in packages
        for path in (root / package).rglob("*.py")
        if "__pycache__" not in path.relative_to(root).parts
    }
    pending = [path for path, source in sources.items() if source and _IMPORTS_NUMBA.search(source)]
    covered = set(pending)
    while pending:
        source = sources.get(pending.pop())
        if source is None:
            continue
        for path in _imported(root, packages, source):
            if path not in covered:
                covered.add(path)
                pending.append(path)
    return sorted(path for path in covered if sources.get(path) is not None)


def source_fingerprint(root: Path = ROOT, packages: Sequence[str] = PACKAGES) -> str:
    """SHA-256 (hex, 16 digits) of :func:`fingerprinted_files`: each one's path relative to
    ``root`` and its bytes, in sorted order."""
    digest = hashlib.sha256()
    for path in fingerprinted_files(root, packages):
        source = _read(path)
        if source is None:
            continue
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(b"\0")
        digest.update(source)
        digest.update(b"\0")
    return digest.hexdigest()[:16]


def cache_base() -> Path:
    """Where the fingerprinted directories live: ``$NUMBA_CACHE_DIR/wip-gym`` if the user set
    ``NUMBA_CACHE_DIR``, else ``~/.cache/wip-gym/compiled``."""
    user = os.environ.get("NUMBA_CACHE_DIR")
    if user:
        return Path(user) / "wip-gym"
    return Path.home() / ".cache" / "wip-gym" / "compiled"


def configure(root: Path = ROOT, packages: Sequence[str] = PACKAGES) -> Path:
    """Point numba's cache at ``cache_base() / source_fingerprint(root, packages)`` for the
    functions defined from now on (module docstring); returns the directory."""
    from numba.core import config

    directory = cache_base() / source_fingerprint(root, packages)
    # numba's setting, set from NUMBA_CACHE_DIR when numba is imported (hence untyped)
    config.CACHE_DIR = str(directory)  # type: ignore[attr-defined]
    return directory
