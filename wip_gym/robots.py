"""The robots wip-gym ships, and what the Python side needs to know about each.

Everything else (wheel radius, separation, joints, limits) is read from the MJCF itself, which
follows the contract of ``assets/mjcf/README.md``.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class RobotSpec:
    """One robot of the gym.

    Attributes:
        name: short name (``wip``, ``planar7``, ``krang``).
        scene_file: MJCF scene (robot + floor + lights + goal marker) in ``assets/mjcf``.
        planar: True when the base moves in the x-z plane only (slide x, slide z, pitch hinge).
        push_body: body at whose CoM pushes act (docs/DESIGN.md §6: the torso's CoM).
        tray_capable: True when the robot has an ``ee`` and ``tray_mount`` site for tray tasks.
    """

    name: str
    scene_file: str
    planar: bool
    push_body: str
    tray_capable: bool


ROBOTS: dict[str, RobotSpec] = {
    "wip": RobotSpec("wip", "scene_wip.xml", planar=False, push_body="base", tray_capable=False),
    "planar7": RobotSpec(
        "planar7", "scene_planar7.xml", planar=True, push_body="torso", tray_capable=True
    ),
    "krang": RobotSpec(
        "krang", "scene_krang.xml", planar=False, push_body="torso", tray_capable=True
    ),
}


def robot_spec(name: str) -> RobotSpec:
    """The spec of a robot by name, with a clear error for unknown names."""
    try:
        return ROBOTS[name]
    except KeyError:
        raise ValueError(f"unknown robot {name!r}; valid: {sorted(ROBOTS)}") from None
