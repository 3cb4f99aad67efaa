"""``wip_gym.compiled_cache``: numba's cache in a directory keyed on the packages' compiled
sources and the modules they import, so that a caller's cache goes stale with an edit of its
callee's file or of a constant it reads from a file without compiled code.

numba keys a cached function on its own file only: a caller compiled with a callee of another
file keeps the callee's old code after an edit of that file. The first tests show it with real
numba in fresh processes (the hazard with numba's own key, and that the keyed directory removes
it; a process started before the edit included); the others hold the fingerprint and this
process's setting."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numba
import pytest

from wip_gym.compiled_cache import (
    PACKAGES,
    ROOT,
    cache_base,
    configure,
    fingerprinted_files,
    source_fingerprint,
)

REPOSITORY = Path(__file__).resolve().parent.parent

CALLEE = "from numba import njit\n\n\n@njit(cache=True)\ndef g():\n    return {value}\n"
CALLER = (
    "from numba import njit\n\nfrom pkg.b import g\nfrom pkg.constants import SCALE\n\n\n"
    "@njit(cache=True)\ndef f():\n    return g() * SCALE\n"
)
CONSTANTS = '"""No compiled code: a constant the caller freezes into its code."""\nSCALE = {}\n'
# the caller's process: the keyed directory configured for pkg or numba's own cache, then
# (optionally) a pause between defining the functions and compiling them, for an edit between
RUN = """
import sys, time
from pathlib import Path
sys.path[:0] = [{root!r}, {repository!r}]
if {keyed}:
    import importlib.util
    spec = importlib.util.spec_from_file_location("compiled_cache", {module!r})
    compiled_cache = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(compiled_cache)
    print("directory", compiled_cache.configure(Path({root!r}), ("pkg",)))
from pkg.a import f
if {pause}:
    Path({root!r}, "ready").touch()
    while not Path({root!r}, "go").exists():
        time.sleep(0.01)
print(f())
"""


def _package(root: Path, value: int, scale: int = 1) -> None:
    package = root / "pkg"
    package.mkdir(parents=True, exist_ok=True)
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text(CALLER)
    (package / "b.py").write_text(CALLEE.format(value=value))
    (package / "constants.py").write_text(CONSTANTS.format(scale))


def _script(root: Path, keyed: bool, pause: bool = False) -> list[str]:
    module = str(REPOSITORY / "wip_gym" / "compiled_cache.py")  # not the package: no import
    script = RUN.format(
        root=str(root), repository=str(REPOSITORY), module=module, keyed=keyed, pause=pause
    )
    return [sys.executable, "-c", script]


def _env(home: Path, cache_dir: Path | None = None) -> dict[str, str]:
    drop = ("NUMBA_CACHE_DIR", "NUMBA_DEBUG_CACHE", "HOME")
    env = {k: v for k, v in os.environ.items() if k not in drop}
    env["HOME"] = str(home)  # the default base, ~/.cache/wip-gym/compiled, under the test's
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = str(cache_dir)
    env["NUMBA_DEBUG_CACHE"] = "1"  # numba prints its cache's loads and saves
    return env


def _run(root: Path, keyed: bool, cache_dir: Path | None = None) -> tuple[str, str]:
    done = subprocess.run(
        _script(root, keyed),
        env=_env(root / "home", cache_dir),
        capture_output=True,
        text=True,
        timeout=120.0,
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    return lines[-1], "\n".join(lines[:-1])


@pytest.mark.parametrize("edit", ["callee", "constant"])
def test_a_caller_sees_an_edited_callee_or_constant_only_in_the_keyed_directory(
    tmp_path: Path, edit: str
) -> None:
    plain, keyed = tmp_path / "plain", tmp_path / "keyed"
    for root in (plain, keyed):
        _package(root, 1, 3)
        value, log = _run(root, keyed=root == keyed)
        assert value == "3" and "data saved" in log  # compiled and cached
        _package(root, 2, 3) if edit == "callee" else _package(root, 1, 5)
    expected = "6" if edit == "callee" else "5"
    # numba's own key: the caller's file is unchanged, so its stale machine code loads
    value, log = _run(plain, keyed=False)
    assert value == "3" and "data loaded" in log
    # a new directory for the new sources: compiled again from them, then cached there
    value, log = _run(keyed, keyed=True)
    assert value == expected and "data loaded" not in log
    value, again = _run(keyed, keyed=True)
    assert value == expected and "data loaded" in again
    # under ~/.cache/wip-gym/compiled, one directory per fingerprint
    directories = sorted((keyed / "home" / ".cache" / "wip-gym" / "compiled").iterdir())
    assert len(directories) == 2
    assert f"directory {directories[0]}" in log or f"directory {directories[1]}" in log


def test_a_users_numba_cache_dir_holds_the_keyed_directories(tmp_path: Path) -> None:
    _package(tmp_path, 1)
    user = tmp_path / "mine"
    value, log = _run(tmp_path, keyed=True, cache_dir=user)
    assert value == "1"
    keyed = user / "wip-gym" / source_fingerprint(tmp_path, ("pkg",))
    assert f"directory {keyed}" in log and any(keyed.rglob("*.nbi"))
    assert not (tmp_path / "home" / ".cache").exists()


def test_a_process_started_before_the_edit_leaves_no_stale_cache(tmp_path: Path) -> None:
    """A process that defined its functions before the edit compiles them with the old callee
    (its code is in memory) and caches them: in its own, old directory, which later processes
    do not take."""
    _package(tmp_path, 1)
    early = subprocess.Popen(
        _script(tmp_path, keyed=True, pause=True),
        env=_env(tmp_path / "home"),
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
    _package(tmp_path, 2)
    (tmp_path / "go").touch()
    out, err = early.communicate(timeout=120.0)
    assert early.returncode == 0, err
    assert out.strip().splitlines()[-1] == "1"  # its own, older code
    assert "data saved" in out
    (tmp_path / "ready").unlink()
    value, log = _run(tmp_path, keyed=True)
    assert value == "2" and "data loaded" not in log


def test_the_fingerprint_covers_the_compiled_sources_and_what_they_import(tmp_path: Path) -> None:
    """Files that import numba count, and the packages' modules they import (through each
    other too); a file no compiled file imports, a cache directory's file and an editor's
    dangling lock link do not (and do not break it)."""
    _package(tmp_path, 1)
    package = tmp_path / "pkg"
    (package / "constants.py").write_text("from pkg.deeper import SCALE\n")
    (package / "deeper.py").write_text("SCALE = 1\n")
    first = source_fingerprint(tmp_path, ("pkg",))
    assert [p.name for p in fingerprinted_files(tmp_path, ("pkg",))] == [
        "a.py", "b.py", "constants.py", "deeper.py"
    ]  # fmt: skip
    (package / "plain.py").write_text('"""numba is not imported here."""\nx = 1\n')
    (package / "__pycache__").mkdir()
    (package / "__pycache__" / "old.py").write_text("import numba\n")
    (package / ".#a.py").symlink_to(tmp_path / "nowhere")
    assert source_fingerprint(tmp_path, ("pkg",)) == first
    (package / "deeper.py").write_text("SCALE = 2\n")  # two imports away from compiled code
    second = source_fingerprint(tmp_path, ("pkg",))
    assert second != first
    (package / "b.py").rename(package / "c.py")
    assert source_fingerprint(tmp_path, ("pkg",)) not in (first, second)


def test_this_process_caches_in_the_directory_of_this_trees_fingerprint() -> None:
    """``import wip_gym`` (this module's imports made it) set numba's cache directory; a
    compiled function of the packages caches there; configuring again gives the same one."""
    from wip_gym.small_linalg import gram_into

    directory = cache_base() / source_fingerprint(ROOT, PACKAGES)
    assert str(directory) == numba.config.CACHE_DIR
    assert gram_into._cache.cache_path.startswith(str(directory))
    assert configure() == directory
    files = {path.relative_to(ROOT).as_posix() for path in fingerprinted_files(ROOT, PACKAGES)}
    # the compiled files, and the modules whose constants they read (the scene's sizes)
    assert {"wip_gym/small_linalg.py", "wip_gym/envs/measures.py", "wip_gym/scene.py"} <= files
    assert "controllers/hierarchical.py" not in files
