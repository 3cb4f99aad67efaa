"""Where the MJCF files are, installed or in a source checkout.

A wheel carries ``assets/mjcf`` as ``wip_gym/_assets/mjcf`` (pyproject's force-include); an
editable install or a bare checkout reads the repository's top-level ``assets/mjcf``.
"""

from __future__ import annotations

from pathlib import Path

_PACKAGE_DIR = Path(__file__).resolve().parent
_CANDIDATES = (_PACKAGE_DIR / "_assets" / "mjcf", _PACKAGE_DIR.parent / "assets" / "mjcf")


def mjcf_dir() -> Path:
    """The folder holding the robot and scene MJCF files."""
    for candidate in _CANDIDATES:
        if (candidate / "common.xml").is_file():
            return candidate
    searched = ", ".join(str(c) for c in _CANDIDATES)
    raise FileNotFoundError(f"wip-gym MJCF assets not found (looked in {searched})")


def mjcf_path(filename: str) -> Path:
    """Absolute path of one MJCF file, e.g. ``mjcf_path("scene_krang.xml")``."""
    path = mjcf_dir() / filename
    if not path.is_file():
        available = sorted(p.name for p in mjcf_dir().glob("*.xml"))
        raise FileNotFoundError(f"no MJCF file {filename!r}; available: {available}")
    return path
