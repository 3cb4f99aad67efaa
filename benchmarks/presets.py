"""Named scenario presets of ``wip-bench compare --preset``: the env side (the controllers'
side is each config's constructor of the same name, ``default_config(name, preset=...)``).

``paper``: the comparison as the authors ran it (docs/AUTHORS_CONFIG.md §5.3): a 5 m drive
straight ahead; in tray tasks the tray a free body resting on the hand(s) with a 5 mm rim,
friction 0.3 tray-cup and tray-hand. The plan and controller settings (the authors' DDP weights,
no acceleration cap, the unified controller's task weights) come from ``Config.paper()``.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from typing import Any

PRESET_NAMES = ("paper",)


def add_configuration_arguments(parser: argparse.ArgumentParser, set_help: str) -> None:
    """``--preset`` and the repeatable ``--set KEY=VALUE`` (into ``args.overrides``), the
    configuration arguments of ``wip-bench compare`` and of every tool that takes its keys
    (``wip-bench profile``, ``tools/lurch_trace.py``); ``set_help`` says which keys."""
    parser.add_argument(
        "--preset",
        choices=PRESET_NAMES,
        help="a named configuration: paper = the authors' (5 m straight, free tray with rim, "
        "the configs' .paper())",
    )
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", dest="overrides", help=set_help
    )


PAPER_GOAL_M = 5.0  # docs/AUTHORS_CONFIG.md §5.3: 5 m straight ahead
PAPER_TRAY = {  # docs/AUTHORS_CONFIG.md §5.3: the authors' tray and cup
    "tray_attachment": "free",
    "tray_rim": 0.005,
    "cup_friction": 0.3,
    "tray_friction": 0.3,
}


def env_arguments(
    preset: str | None, env_id: str, settings: Mapping[str, Any]
) -> tuple[dict[str, Any], list[str]]:
    """The preset's env arguments for ``env_id`` (``settings``: its ``env.<argument>`` keys)
    and an empty list (kept for callers; every preset argument must exist)."""
    if preset is None:
        return {}, []
    if preset not in PRESET_NAMES:
        raise ValueError(f"unknown preset {preset!r}; valid: {list(PRESET_NAMES)}")
    from benchmarks.overrides import is_planar

    wanted: dict[str, Any] = {"goal": PAPER_GOAL_M if is_planar(env_id) else (PAPER_GOAL_M, 0.0)}
    if "env.cup_friction" in settings and "Tray" in env_id:
        wanted.update(PAPER_TRAY)
    unknown = [k for k in wanted if f"env.{k}" not in settings]
    if unknown:
        raise ValueError(f"--preset {preset}: {env_id} has no arguments {unknown}")
    return wanted, []
