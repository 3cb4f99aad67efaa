"""The floor the wheels roll over: a slope and bumps, as MuJoCo geometry (docs/realism.md §5).

The scene files hold a flat floor plane through the origin (``assets/mjcf/floor.xml``). This
module changes it in a task's ``MjSpec`` before it is compiled:

* **slope** (``slope_deg``): the floor plane turned about the world y axis so that it rises
  toward +x (negative: falls). The robot's reset puts its wheels on it (:func:`axle_lift`); the
  goal marker sits on it.
* **bumps** (``bump_height``, ``bump_spacing``, ``bump_width``): boxes across the path, their
  flat tops ``bump_height`` above the floor surface, ``bump_width`` long along x, every
  ``bump_spacing`` metres along the floor surface from the start (none at the start), over the
  course from start to goal and 5 m beyond either end, 5 m to each side of the path. They lie
  on the slope.

The bumps meet the **wheels only**: contype 8 and conaffinity 0, and the wheel collision geoms
get conaffinity bit 8 (the robot's links keep theirs, so a link passes through a bump and a
fall is still found where a link touches the floor plane, ``floor``, as without bumps). A
wheel meets a bump with the wheel's own contact parameters (its ``priority`` 1): the same
nearly hard contact and friction as on the floor.

With every argument at its default nothing in the spec is touched.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

#: the collision bit the bumps and the wheels share (the robot uses 1 and 2, the cup and the
#: free tray 4)
BUMP_COLLISION_BIT = 8
#: bumps run this far beyond the course's ends (start and goal) and to each side of the path (m)
BUMPS_MARGIN = 5.0
BUMPS_HALF_LENGTH = 5.0
#: how deep a bump's box reaches below the floor surface (m): no gap at its foot on any slope
BUMP_FOOTING = 0.02
#: at most this many bumps in a scene (a spacing too small for the course is an error)
MAX_BUMPS = 400
MAX_SLOPE_DEG = 30.0
WHEEL_GEOMS = ("wheel_left", "wheel_right")


@dataclass(frozen=True)
class FloorOptions:
    """The floor's shape.

    Attributes:
        slope_deg: the floor's inclination about the world y axis (deg), rising toward +x when
            positive; within +-30.
        bump_height: height (m) of the bumps' flat tops above the floor surface, 0 for none.
        bump_spacing: distance (m) between bumps along the floor surface (the first one
            ``bump_spacing`` from the start).
        bump_width: length (m) of each bump's top along the path.
    """

    slope_deg: float = 0.0
    bump_height: float = 0.0
    bump_spacing: float = 1.0
    bump_width: float = 0.1

    def __post_init__(self) -> None:
        for name in ("slope_deg", "bump_height", "bump_spacing", "bump_width"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"{name} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ValueError(f"{name} must be finite, got {value!r}")
        if abs(self.slope_deg) > MAX_SLOPE_DEG:
            raise ValueError(
                f"floor_slope_deg must be within +-{MAX_SLOPE_DEG}, got {self.slope_deg!r}"
            )
        if self.bump_height < 0:
            raise ValueError(f"bump_height must be >= 0, got {self.bump_height!r}")
        if self.bump_width <= 0 or self.bump_spacing <= self.bump_width:
            raise ValueError(
                f"bumps need 0 < bump_width < bump_spacing, got width {self.bump_width!r}, "
                f"spacing {self.bump_spacing!r}"
            )

    @property
    def flat(self) -> bool:
        """No slope and no bumps: the scene's floor as it is."""
        return self.slope_deg == 0.0 and self.bump_height == 0.0

    @property
    def slope_rad(self) -> float:
        return math.radians(self.slope_deg)


def axle_lift(options: FloorOptions, wheel_radius: float) -> float:
    """How much higher (m) the axle of a robot standing at the origin is on the slope than on
    the flat floor: a spherical wheel touches the plane where its normal through the wheel's
    centre meets it, so the centre is ``r`` from the plane along the normal, ``r / cos(alpha)``
    above the origin."""
    return wheel_radius / math.cos(options.slope_rad) - wheel_radius


def floor_height(options: FloorOptions, x: float) -> float:
    """The floor plane's height (m) at world ``x`` (bumps not included)."""
    return x * math.tan(options.slope_rad)


def _slope_quat(alpha: float) -> np.ndarray:
    """The rotation about world y that takes z to the plane's normal ``(-sin a, 0, cos a)``."""
    return np.array([math.cos(-alpha / 2), 0.0, math.sin(-alpha / 2), 0.0])


def bump_positions(options: FloorOptions, goal: tuple[float, float]) -> list[float]:
    """Where the bumps' centres are along the floor surface from the start (m): every
    ``bump_spacing``, none at the start, ``BUMPS_MARGIN`` beyond the start and the goal's x
    either way. ``ValueError`` beyond ``MAX_BUMPS``."""
    if options.bump_height == 0.0:
        return []
    ahead = max(goal[0], 0.0) + BUMPS_MARGIN
    behind = max(-goal[0], 0.0) + BUMPS_MARGIN
    n_ahead = int(math.floor(ahead / options.bump_spacing))
    n_behind = int(math.floor(behind / options.bump_spacing))
    if n_ahead + n_behind > MAX_BUMPS:
        raise ValueError(
            f"bump_spacing {options.bump_spacing} m puts {n_ahead + n_behind} bumps on the "
            f"course (at most {MAX_BUMPS})"
        )
    return [k * options.bump_spacing for k in range(-n_behind, n_ahead + 1) if k != 0]


def check_start_clear(options: FloorOptions, wheel_radius: float) -> None:
    """``ValueError`` if the nearest bumps would touch a wheel at the start: a sphere of radius
    ``r`` meets a box edge of height ``h`` within ``sqrt(2 r h - h^2)`` of its centre."""
    if options.bump_height == 0.0:
        return
    h = min(options.bump_height, wheel_radius)
    reach = math.sqrt(2.0 * wheel_radius * h - h * h)
    if options.bump_spacing - options.bump_width / 2 <= reach:
        raise ValueError(
            f"bump_spacing {options.bump_spacing} and bump_width {options.bump_width} put "
            f"bumps that touch the wheels at the start (a wheel of radius {wheel_radius} m "
            f"meets a {options.bump_height} m edge {reach:.3f} m from its centre)"
        )


def shape_floor(spec: mujoco.MjSpec, options: FloorOptions, goal: tuple[float, float]) -> None:
    """Slope the floor and add the bumps in ``spec`` (which holds ``floor.xml``'s ``floor``
    plane and ``goal`` site and the robot's wheel geoms); nothing when ``options.flat``.
    ``goal``: the task's goal ``(X, Y)``, which decides how far the bumps run and where the goal
    marker sits on the slope."""
    if options.flat:
        return
    alpha = options.slope_rad
    quat = _slope_quat(alpha)
    if alpha != 0.0:
        spec.geom("floor").quat = quat
        marker = spec.site("goal")
        marker.pos = [goal[0], goal[1], floor_height(options, goal[0]) + marker.pos[2]]
        marker.quat = quat
    positions = bump_positions(options, goal)
    if not positions:
        return
    for name in WHEEL_GEOMS:
        wheel = spec.geom(name)
        wheel.conaffinity = wheel.conaffinity | BUMP_COLLISION_BIT
    h, depth = options.bump_height, BUMP_FOOTING
    half = (options.bump_width / 2, abs(goal[1]) + BUMPS_HALF_LENGTH, (h + depth) / 2)
    c, s = math.cos(alpha), math.sin(alpha)
    centre_up = (h - depth) / 2  # above the floor surface, along its normal
    for k, along in enumerate(positions):
        # a point ``along`` the surface and ``centre_up`` along the normal (-s, 0, c)
        spec.worldbody.add_geom(
            name=f"bump{k}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=half,
            pos=[along * c - centre_up * s, 0.0, along * s + centre_up * c],
            quat=quat,
            contype=BUMP_COLLISION_BIT,
            conaffinity=0,
            condim=3,
            material="grid",
        )
