"""Cameras computed from the state each frame: the robot framed from the side of its drive.

MuJoCo's ``trackcom`` camera follows the centre of mass but never yaws, so a 3-D robot that
turns drives towards or away from it. The cameras here are free ``mjvCamera`` poses computed
from ``mjData`` every frame instead:

- ``follow`` (every env's default): looks at the robot's middle, from its right-hand side
  (perpendicular to the heading, so the robot drives left to right and the view turns with it),
  at the distance that makes the robot about two thirds of the frame high;
- ``tray``: a close-up of the tray and the cup (or of the hand, on a robot without a tray),
  from the front-right and above, so the cup's slide on the plate is visible.

Any camera of the MJCF (``track``) is accepted by name too (a fixed camera). A camera pose is a
pure function of the model and ``mjData`` (no history, no body masses), so a replay of a
recorded state frames it exactly as the live episode did.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

FOLLOW = "follow"
TRAY = "tray"
COMPUTED_CAMERAS = (FOLLOW, TRAY)


@dataclass(frozen=True)
class CameraConfig:
    """How the computed cameras frame the robot (chosen by eye on every registered env).

    Attributes:
        height_fraction: the robot's reset height over the frame's height in the look-at plane;
            its near side is closer, so its silhouette is ~15 % taller (68 % measured at 0.6, the
            "two thirds of the frame" asked for).
        elevation_deg: ``follow``'s elevation (negative: looking down), a little above the
            axle so the floor's grid shows the motion.
        tray_distance_m: ``tray``'s distance from the plate's top centre.
        tray_azimuth_deg: ``tray``'s azimuth from the ``follow`` direction towards the front.
        tray_elevation_deg: ``tray``'s elevation (looking down onto the plate).
    """

    height_fraction: float = 0.6
    elevation_deg: float = -12.0
    tray_distance_m: float = 1.1
    tray_azimuth_deg: float = 55.0
    tray_elevation_deg: float = -40.0


def camera_names(model: mujoco.MjModel) -> list[str]:
    """Every camera name valid for ``model``: the computed ones, then the MJCF's."""
    names = [FOLLOW]
    if _tray_target(model) is not None:
        names.append(TRAY)
    names += [model.camera(i).name for i in range(model.ncam)]
    return names


def _tray_target(model: mujoco.MjModel) -> tuple[str, int] | None:
    """What ``tray`` looks at: the tray's top site, else the hand's ``ee`` site."""
    for site in ("tray_top", "ee"):
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, site)
        if sid >= 0:
            return site, sid
    return None


def robot_geoms(model: mujoco.MjModel) -> NDArray[np.int64]:
    """The visible geoms of the robot's tree (everything rooted at ``base``, tray and payload
    included), i.e. what a viewer sees as the robot."""
    base = model.body("base").id
    root = model.body_rootid[base]
    visible = model.geom_rgba[:, 3] > 0
    drawn = model.geom_group < 3  # groups 0-2 are drawn by default
    in_tree = model.body_rootid[model.geom_bodyid] == root
    return np.flatnonzero(in_tree & visible & drawn)


def _heading(data: mujoco.MjData, base: int) -> float:
    """The robot's heading angle (rad) from its axle: the base's y axis is the wheel axis, so
    the heading is that axis turned by -90 deg (robust to the base's pitch)."""
    y_axis = data.xmat[base].reshape(3, 3)[:, 1]
    return math.atan2(-y_axis[0], y_axis[1])


class TrackingCamera:
    """A computed camera (``follow`` or ``tray``) for one model.

    The robot's size is measured once, at the noise-free reset pose: its visible geoms' bounding
    box in the heading frame gives the height (hence the distance) and the box's middle
    relative to the axle (hence the look-at point), so the framing does not jitter as the arms
    move.
    """

    def __init__(
        self, model: mujoco.MjModel, name: str = FOLLOW, config: CameraConfig | None = None
    ) -> None:
        if name not in COMPUTED_CAMERAS:
            raise ValueError(f"unknown computed camera {name!r}; valid: {list(COMPUTED_CAMERAS)}")
        self.name = name
        self.config = config or CameraConfig()
        self._base = model.body("base").id
        self._fovy = math.radians(model.vis.global_.fovy)
        target = _tray_target(model)
        if name == TRAY and target is None:
            raise ValueError(f"camera 'tray' needs a tray or a hand; valid: {camera_names(model)}")
        self._site = -1 if target is None else target[1]
        low, high = self._robot_box(model)
        self._middle = 0.5 * (low + high)  # heading frame, relative to the axle (x, z used)
        self._size = high - low  # (length along the heading, width, height)

    @staticmethod
    def _robot_box(model: mujoco.MjModel) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The robot's bounding box at its reset pose, in the heading frame at the axle."""
        from wip_gym.scene import reset_qpos  # here: scene imports the robot model

        data = mujoco.MjData(model)
        pose = reset_qpos(model)
        data.qpos[: len(pose)] = pose
        mujoco.mj_kinematics(model, data)
        base = model.body("base").id
        psi = _heading(data, base)
        rotation = np.array(
            [[math.cos(psi), -math.sin(psi), 0.0], [math.sin(psi), math.cos(psi), 0.0], [0, 0, 1]]
        )
        axle = data.xpos[base]
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        points = []
        for g in robot_geoms(model):
            centre, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
            local = centre + corners * half
            world = data.geom_xpos[g] + local @ data.geom_xmat[g].reshape(3, 3).T
            points.append((world - axle) @ rotation)
        stacked = np.concatenate(points)
        low, high = stacked.min(axis=0), stacked.max(axis=0)
        low[2] = -axle[2]  # from the floor up (the wheels touch it)
        return low, high

    @property
    def robot_height(self) -> float:
        """The robot's height (m) at reset, floor to top."""
        return float(self._size[2])

    def distance(self, aspect: float) -> float:
        """``follow``'s distance: the robot ``height_fraction`` of the frame high, and its length
        at most 80 % of the frame wide (``aspect`` = width / height)."""
        tan_half = math.tan(0.5 * self._fovy)
        by_height = self._size[2] / self.config.height_fraction / (2.0 * tan_half)
        by_length = self._size[0] / 0.8 / (2.0 * tan_half * aspect)
        return max(by_height, by_length)

    def update(self, camera: mujoco.MjvCamera, data: mujoco.MjData, aspect: float) -> None:
        """Set ``camera`` (a free camera) for the state in ``data`` (kinematics up to date)."""
        psi = _heading(data, self._base)
        cos, sin = math.cos(psi), math.sin(psi)
        camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        side = math.degrees(psi) + 90.0  # looking along the robot's left: from its right side
        if self.name == FOLLOW:
            axle = data.xpos[self._base]
            forward = self._middle[0]
            up = axle[2] + self._middle[2]
            camera.lookat[:] = (axle[0] + cos * forward, axle[1] + sin * forward, up)
            camera.distance = self.distance(aspect)
            camera.azimuth = side
            camera.elevation = self.config.elevation_deg
        else:
            camera.lookat[:] = data.site_xpos[self._site]
            camera.distance = self.config.tray_distance_m
            camera.azimuth = side + self.config.tray_azimuth_deg
            camera.elevation = self.config.tray_elevation_deg
