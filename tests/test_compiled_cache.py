"""``wip_gym.compiled_cache``: numba's caches keyed on every compiled source file of a package
set, so that a caller's cache goes stale with an edit of its callee's file.

numba keys a cached function on its own file only: a caller compiled with a callee of another
file keeps the callee's old code after an edit of that file. The first tests show it with real
numba in fresh processes (the hazard, and that the fingerprint removes it, in the tree's cache
and in ``NUMBA_CACHE_DIR``; a process started before the edit included); the others hold the
fingerprint and the installation in this process."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numba
import pytest

from wip_gym.compiled_cache import PACKAGES, fingerprint_of, install, source_fingerprint

REPOSITORY = Path(__file__).resolve().parent.parent

CALLEE = "from numba import njit\n\n\n@njit(cache=True)\ndef g():\n    return {value}\n"
CALLER = (
    "from numba import njit\n\nfrom pkg.b import g\n\n\n"
    "@njit(cache=True)\ndef f():\n    return g()\n"
)
# the caller's process: the fingerprint installed for pkg or not, then (optionally) a pause
# between defining the functions and compiling them, for an edit in between
RUN = """
import sys, time
from pathlib import Path
sys.path[:0] = [{root!r}, {repository!r}]
if {fingerprinted}:
    import importlib.util
    spec = importlib.util.spec_from_file_location("compiled_cache", {module!r})
    compiled_cache = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(compiled_cache)
    compiled_cache.install(Path({root!r}), ("pkg",))
from pkg.a import f
if {pause}:
    Path({root!r}, "ready").touch()
    while not Path({root!r}, "go").exists():
        time.sleep(0.01)
print(f())
"""


def _package(root: Path, value: int) -> None:
    package = root / "pkg"
    package.mkdir(parents=True, exist_ok=True)
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text(CALLER)
    (package / "b.py").write_text(CALLEE.format(value=value))


def _script(root: Path, fingerprinted: bool, pause: bool = False) -> list[str]:
    module = str(REPOSITORY / "wip_gym" / "compiled_cache.py")  # not the package: no import
    script = RUN.format(
        root=str(root),
        repository=str(REPOSITORY),
        module=module,
        fingerprinted=fingerprinted,
        pause=pause,
    )
    return [sys.executable, "-c", script]


def _env(cache_dir: Path | None) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "NUMBA_DEBUG_CACHE")}
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = str(cache_dir)
    env["NUMBA_DEBUG_CACHE"] = "1"  # numba prints its cache's loads and saves
    return env


def _run(root: Path, fingerprinted: bool, cache_dir: Path | None = None) -> tuple[str, str]:
    done = subprocess.run(
        _script(root, fingerprinted),
        env=_env(cache_dir),
        capture_output=True,
        text=True,
        timeout=120.0,
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    return lines[-1], "\n".join(lines[:-1])


@pytest.mark.parametrize("where", ["tree", "NUMBA_CACHE_DIR"])
def test_a_caller_sees_its_edited_callee_only_with_the_fingerprint(
    tmp_path: Path, where: str
) -> None:
    cache_dir = tmp_path / "cache" if where == "NUMBA_CACHE_DIR" else None
    plain, keyed = tmp_path / "plain", tmp_path / "keyed"
    for root in (plain, keyed):
        _package(root, 1)
        value, log = _run(root, fingerprinted=root == keyed, cache_dir=cache_dir)
        assert value == "1" and "data saved" in log  # compiled and cached
        (root / "pkg" / "b.py").write_text(CALLEE.format(value=2))  # the callee edited
    # numba's own key: the caller's file is unchanged, so its stale machine code loads
    value, log = _run(plain, fingerprinted=False, cache_dir=cache_dir)
    assert value == "1" and "data loaded" in log
    # keyed on the package's compiled sources: stale, compiled again from the current ones
    value, log = _run(keyed, fingerprinted=True, cache_dir=cache_dir)
    assert value == "2" and "data loaded" not in log
    value, log = _run(keyed, fingerprinted=True, cache_dir=cache_dir)
    assert value == "2" and "data loaded" in log  # and cached again


def test_a_process_started_before_the_edit_leaves_no_stale_cache(tmp_path: Path) -> None:
    """A process that defined its functions before the edit compiles them with the old callee
    (its code is in memory) and caches them: under its own, old fingerprint, which later
    processes do not take."""
    _package(tmp_path, 1)
    early = subprocess.Popen(
        _script(tmp_path, fingerprinted=True, pause=True),
        env=_env(None),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 120.0
    while not (tmp_path / "ready").exists():
        if early.poll() is not None or time.monotonic() > deadline:
            early.kill()
            pytest.fail(f"the early process did not get ready: {early.communicate()}")
        time.sleep(0.01)
    (tmp_path / "pkg" / "b.py").write_text(CALLEE.format(value=2))
    (tmp_path / "go").touch()
    out, err = early.communicate(timeout=120.0)
    assert early.returncode == 0, err
    assert out.strip().splitlines()[-1] == "1"  # its own, older code
    assert "data saved" in out
    (tmp_path / "ready").unlink()
    value, log = _run(tmp_path, fingerprinted=True)
    assert value == "2" and "data loaded" not in log


def test_the_fingerprint_covers_the_compiled_sources_only(tmp_path: Path) -> None:
    """Files that import numba count; a file that only names it, a cache directory's file and
    an editor's dangling lock link do not (and do not break it); a file seen through a
    symbolic link to the package gets the package's fingerprint."""
    _package(tmp_path, 1)
    first = source_fingerprint(tmp_path, ("pkg",))
    (tmp_path / "pkg" / "plain.py").write_text('"""numba is not imported here."""\nx = 1\n')
    (tmp_path / "pkg" / "__pycache__").mkdir()
    (tmp_path / "pkg" / "__pycache__" / "old.py").write_text("import numba\n")
    (tmp_path / "pkg" / ".#a.py").symlink_to(tmp_path / "nowhere")
    assert source_fingerprint(tmp_path, ("pkg",)) == first
    (tmp_path / "pkg" / "b.py").write_text(CALLEE.format(value=2))
    second = source_fingerprint(tmp_path, ("pkg",))
    assert second != first
    (tmp_path / "pkg" / "b.py").rename(tmp_path / "pkg" / "c.py")
    assert source_fingerprint(tmp_path, ("pkg",)) not in (first, second)
    link = tmp_path.parent / f"{tmp_path.name}-link"
    link.symlink_to(tmp_path, target_is_directory=True)
    install(tmp_path, ("pkg",))
    assert fingerprint_of(str(link / "pkg" / "a.py")) == source_fingerprint(tmp_path, ("pkg",))
    assert fingerprint_of(str(tmp_path / "elsewhere.py")) is None


def test_this_process_keys_the_packages_caches_on_their_fingerprint() -> None:
    """``import wip_gym`` (this module's imports made it) installed the locators first in
    numba's list; a compiled function of the packages carries the fingerprint of this tree's
    compiled sources in its cache's key, and installing again changes nothing."""
    from numba.core import caching

    from wip_gym.small_linalg import gram_into

    names = [cls.__name__ for cls in caching.CacheImpl._locator_classes]
    assert names[:3] == [
        "FingerprintedUserProvidedCacheLocator",
        "FingerprintedInTreeCacheLocator",
        "FingerprintedUserWideCacheLocator",
    ]
    _, fingerprint = gram_into._cache._cache_file._source_stamp
    assert fingerprint == source_fingerprint(REPOSITORY, PACKAGES)
    assert install()
    assert [cls.__name__ for cls in caching.CacheImpl._locator_classes] == names
    # a function of a file outside the packages keeps numba's own locator and key
    assert type(_outside._cache._impl.locator).__name__ == "InTreeCacheLocator"
    assert isinstance(_outside._cache._cache_file._source_stamp, bytes)


@numba.njit(cache=True)
def _outside() -> int:
    return 1
