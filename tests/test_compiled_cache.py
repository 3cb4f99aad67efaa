"""``wip_gym.compiled_cache``: numba's caches cleared when the compiled code's sources change.

numba keys a cached function on its own file only; a caller compiled with a callee of another
file keeps the callee's old code after an edit of that file. The first test shows it with real
numba in fresh processes (the hazard, and that the guard removes it); the others hold the
guard's bookkeeping: what it deletes, when, and what it leaves."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from wip_gym.compiled_cache import STAMP, drop_stale_caches, source_fingerprint

REPOSITORY = Path(__file__).resolve().parent.parent

CALLEE = "from numba import njit\n\n\n@njit(cache=True)\ndef g():\n    return {value}\n"
CALLER = (
    "from numba import njit\n\nfrom pkg.b import g\n\n\n"
    "@njit(cache=True)\ndef f():\n    return g()\n"
)
RUN = """
import sys
sys.path[:0] = [{root!r}, {repository!r}]
if {guard}:
    from pathlib import Path
    from wip_gym.compiled_cache import drop_stale_caches
    drop_stale_caches(Path({root!r}), ("pkg",))
from pkg.a import f
print(f())
"""


def _package(root: Path, value: int) -> None:
    package = root / "pkg"
    package.mkdir(exist_ok=True)
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text(CALLER)
    (package / "b.py").write_text(CALLEE.format(value=value))


def _run(root: Path, guard: bool) -> str:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    script = RUN.format(root=str(root), repository=str(REPOSITORY), guard=guard)
    done = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True
    )
    return done.stdout.strip()


def test_a_caller_sees_its_edited_callee_only_with_the_guard(tmp_path: Path) -> None:
    unguarded, guarded = tmp_path / "unguarded", tmp_path / "guarded"
    for root in (unguarded, guarded):
        root.mkdir()
        _package(root, 1)
        assert _run(root, guard=root == guarded) == "1"  # compiled and cached
        (root / "pkg" / "b.py").write_text(CALLEE.format(value=2))  # the callee edited
    # numba's own cache: the caller's file is unchanged, so its stale machine code loads
    assert _run(unguarded, guard=False) == "1"
    # the guard saw the edit and cleared the caches: compiled again from the sources
    assert _run(guarded, guard=True) == "2"
    assert _run(guarded, guard=True) == "2"  # and cached again


def _caches(root: Path) -> list[str]:
    return sorted(p.name for p in root.rglob("*.nb[ic]"))


def _fake_caches(root: Path) -> None:
    for directory in (root / "pkg" / "__pycache__", root / "pkg" / "sub" / "__pycache__"):
        directory.mkdir(parents=True, exist_ok=True)
        (directory / "a.f-5.py311.nbi").write_text("index")
        (directory / "a.f-5.py311.1.nbc").write_text("code")
        (directory / "a.cpython-311.pyc").write_text("bytecode")


def test_caches_are_cleared_once_per_change_of_the_sources(tmp_path: Path) -> None:
    _package(tmp_path, 1)
    (tmp_path / "pkg" / "sub").mkdir()
    (tmp_path / "pkg" / "sub" / "c.py").write_text("x = 1\n")
    _fake_caches(tmp_path)
    # no fingerprint yet: caches of unknown sources are cleared, bytecode is not
    assert drop_stale_caches(tmp_path, ("pkg",))
    assert _caches(tmp_path) == []
    assert len(list(tmp_path.rglob("*.pyc"))) == 2
    stamp = tmp_path / "pkg" / "__pycache__" / STAMP
    assert stamp.read_text() == source_fingerprint(tmp_path, ("pkg",))
    # the same sources: caches written since are kept
    _fake_caches(tmp_path)
    assert not drop_stale_caches(tmp_path, ("pkg",))
    assert len(_caches(tmp_path)) == 4
    # an edit in a subpackage clears them again, once
    (tmp_path / "pkg" / "sub" / "c.py").write_text("x = 2\n")
    assert drop_stale_caches(tmp_path, ("pkg",))
    assert _caches(tmp_path) == []
    assert not drop_stale_caches(tmp_path, ("pkg",))
    assert [p.name for p in stamp.parent.iterdir() if p.suffix == ".tmp"] == []


def test_the_fingerprint_follows_contents_and_paths(tmp_path: Path) -> None:
    _package(tmp_path, 1)
    first = source_fingerprint(tmp_path, ("pkg",))
    (tmp_path / "pkg" / "__pycache__").mkdir()
    (tmp_path / "pkg" / "__pycache__" / "stale.py").write_text("ignored")
    assert source_fingerprint(tmp_path, ("pkg",)) == first  # caches' directories are not sources
    (tmp_path / "pkg" / "b.py").rename(tmp_path / "pkg" / "b2.py")
    assert source_fingerprint(tmp_path, ("pkg",)) != first


def test_a_user_cache_directory_and_an_unwritable_tree_are_left_alone(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _package(tmp_path, 1)
    _fake_caches(tmp_path)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "elsewhere"))
    assert not drop_stale_caches(tmp_path, ("pkg",))
    assert len(_caches(tmp_path)) == 4
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    # where the fingerprint cannot be written (its directory is a file here: the same error
    # as a read-only tree, whatever the user's permissions), nothing is reported cleared
    other = tmp_path / "other"
    other.mkdir()
    _package(other, 1)
    (other / "pkg" / "__pycache__").write_text("not a directory")
    assert not drop_stale_caches(other, ("pkg",))


def test_this_tree_has_its_fingerprint_after_import() -> None:
    """``import wip_gym`` (this module's imports made it) left the fingerprint of this tree's
    sources beside its caches, unless a cache directory of the user's choosing is in use."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        assert not drop_stale_caches()
        return
    stamp = REPOSITORY / "wip_gym" / "__pycache__" / STAMP
    assert stamp.read_text() == source_fingerprint(REPOSITORY, ("wip_gym", "controllers"))
