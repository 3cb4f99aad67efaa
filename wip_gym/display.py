"""Whether this process can open a window (docs/videos.md §6).

GLFW, which MuJoCo's and Gymnasium's viewers open windows with, aborts the whole process (a C
assertion, exit status 134) when it starts without a display. ``render_mode="human"`` and
``wip-bench view`` ask :func:`require_display` first, and raise :class:`NoDisplayError` with
what to do instead.
"""

from __future__ import annotations

import os
import sys


class NoDisplayError(RuntimeError):
    """A window was asked for where there is no display."""


def display_available() -> bool:
    """On Linux and the BSDs: ``DISPLAY`` (X11) or ``WAYLAND_DISPLAY`` is set. Elsewhere (macOS,
    Windows) a desktop session always has one."""
    if sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd")):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def require_display(what: str) -> None:
    """:class:`NoDisplayError` naming ``what`` when :func:`display_available` is False."""
    if not display_available():
        raise NoDisplayError(
            f"{what} opens a window and needs a display; this process has none (DISPLAY and "
            "WAYLAND_DISPLAY are unset). Without one: render_mode='rgb_array' frames or "
            "videos (docs/videos.md §5), `wip-bench compare --video` and `wip-bench render`; "
            "`wip-bench view` where there is a display (docs/videos.md §6)"
        )
