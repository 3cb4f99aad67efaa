"""Offscreen frames of a model's state through a named camera, with settings chosen for speed,
and renderers that close themselves before the interpreter tears EGL down.

Render settings (``benchmarks/speed/render_cost.py`` at the git tag ``lab-notebook``, 480 x 320,
Mesa llvmpipe on the 2-core development machine while other jobs ran, so +-50 %; median ms per
frame over two runs each of PlanarTray-v0 and KrangTray-v0, and the mean |pixel difference| to
the chosen frame, 0-255):
chosen (no shadows, no reflections, no anti-aliasing) 15-24 ms; with shadows 64-150 ms
(difference 5.4-5.5: the robot's shadow); with 4x multisample anti-aliasing 60-85 ms
(difference 0.24-0.28: edges only); with reflections the identical picture (difference 0: the
floor is not reflective). Links stay apart by their colours and the two lights' shading, so the
fast settings are the default; ``QUALITY`` turns all three on.
"""

from __future__ import annotations

import atexit
import weakref
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal, overload

import mujoco
import numpy as np
from numpy.typing import NDArray

from wip_gym.camera import COMPUTED_CAMERAS, TrackingCamera, camera_names


@dataclass(frozen=True)
class RenderSettings:
    """What a frame costs (defaults: the fast settings, chosen in ``benchmarks/render.py``).

    Attributes:
        shadows: shadow maps for the lights (``mjRND_SHADOW``).
        reflections: floor reflections (``mjRND_REFLECTION``; the floor is not reflective).
        offsamples: multisample anti-aliasing samples of the offscreen buffer (0: none).
        skybox: draw the sky gradient (``mjRND_SKYBOX``).
    """

    shadows: bool = False
    reflections: bool = False
    offsamples: int = 0
    skybox: bool = True

    def __post_init__(self) -> None:
        if self.offsamples not in (0, 2, 4, 8, 16):
            raise ValueError(f"offsamples must be one of 0, 2, 4, 8, 16, got {self.offsamples}")


FAST = RenderSettings()
QUALITY = RenderSettings(shadows=True, reflections=True, offsamples=4)

# Live renderers, closed at exit. MuJoCo's EGL backend registers ``eglTerminate`` with atexit
# when it makes its first context; atexit runs last-registered first, so the hook below is
# registered after that (on the first renderer) and closes every live renderer before EGL
# terminates. Otherwise their finalizers run after it and print EGL tracebacks.
_LIVE: weakref.WeakSet[FrameRenderer] = weakref.WeakSet()
_exit_hook_registered = False


def _close_live_renderers() -> None:
    for renderer in list(_LIVE):
        renderer.close()


def _register_exit_hook() -> None:
    global _exit_hook_registered
    if not _exit_hook_registered:
        atexit.register(_close_live_renderers)
        _exit_hook_registered = True


def check_size(width: int, height: int) -> None:
    """A frame size H.264 accepts: positive and even (yuv420p halves both)."""
    for name, value in (("width", width), ("height", height)):
        if not isinstance(value, int | np.integer) or value < 2 or value % 2:
            raise ValueError(f"{name} must be an even integer >= 2 (H.264), got {value!r}")


class FrameRenderer:
    """Renders ``(model, data)`` to RGB arrays through one camera.

    Args:
        model: the model (its offscreen buffer must be at least ``width`` x ``height``).
        width, height: frame size in pixels (even ones for an H.264 video).
        camera: ``follow`` (default), ``tray`` or an MJCF camera name.
        settings: shadows, reflections, anti-aliasing.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        width: int,
        height: int,
        camera: str = "follow",
        settings: RenderSettings = FAST,
    ) -> None:
        for name, value in (("width", width), ("height", height)):
            if not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        valid = camera_names(model)
        if camera not in valid:
            raise ValueError(f"unknown camera {camera!r}; valid: {valid}")
        self.model = model
        self.width, self.height = int(width), int(height)
        self.camera_name = camera
        self.settings = settings
        offsamples = model.vis.quality.offsamples
        model.vis.quality.offsamples = settings.offsamples
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, self.width)
        model.vis.global_.offheight = max(model.vis.global_.offheight, self.height)
        try:
            self._renderer: mujoco.Renderer | None = mujoco.Renderer(model, self.height, self.width)
        finally:
            model.vis.quality.offsamples = offsamples
        flags = self._renderer.scene.flags
        flags[mujoco.mjtRndFlag.mjRND_SHADOW] = settings.shadows
        flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = settings.reflections
        flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = settings.skybox
        self._camera = mujoco.MjvCamera()
        self._tracking: TrackingCamera | None = None
        if camera in COMPUTED_CAMERAS:
            self._tracking = TrackingCamera(model, camera)
        else:
            self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
            self._camera.fixedcamid = model.camera(camera).id
        self._option = mujoco.MjvOption()
        self._scratch = mujoco.MjData(model)
        _LIVE.add(self)
        _register_exit_hook()  # after the first GL context: runs before eglTerminate

    @overload
    def render(
        self, data: mujoco.MjData, hidden_geoms: Iterable[int] = (), depth: Literal[False] = False
    ) -> NDArray[np.uint8]: ...
    @overload
    def render(
        self, data: mujoco.MjData, hidden_geoms: Iterable[int], depth: Literal[True]
    ) -> NDArray[np.float32]: ...
    @overload
    def render(
        self, data: mujoco.MjData, hidden_geoms: Iterable[int] = (), depth: bool = False
    ) -> NDArray[np.uint8] | NDArray[np.float32]: ...
    def render(
        self, data: mujoco.MjData, hidden_geoms: Iterable[int] = (), depth: bool = False
    ) -> NDArray[np.uint8] | NDArray[np.float32]:
        """The frame of the state ``data.qpos`` (``data`` itself is not touched: after
        ``mj_step`` its kinematics belong to the previous positions, so they are recomputed
        on a private copy); ``hidden_geoms`` are left out of the picture (a payload not yet
        in the hand). ``depth``: the depth image instead (metres)."""
        return self.render_qpos(data.qpos, hidden_geoms, depth, data.mocap_pos, data.mocap_quat)

    @overload
    def render_qpos(
        self,
        qpos: NDArray[np.float64],
        hidden_geoms: Iterable[int] = (),
        depth: Literal[False] = False,
        mocap_pos: NDArray[np.float64] | None = None,
        mocap_quat: NDArray[np.float64] | None = None,
    ) -> NDArray[np.uint8]: ...
    @overload
    def render_qpos(
        self,
        qpos: NDArray[np.float64],
        hidden_geoms: Iterable[int],
        depth: Literal[True],
        mocap_pos: NDArray[np.float64] | None = None,
        mocap_quat: NDArray[np.float64] | None = None,
    ) -> NDArray[np.float32]: ...
    @overload
    def render_qpos(
        self,
        qpos: NDArray[np.float64],
        hidden_geoms: Iterable[int] = (),
        depth: bool = False,
        mocap_pos: NDArray[np.float64] | None = None,
        mocap_quat: NDArray[np.float64] | None = None,
    ) -> NDArray[np.uint8] | NDArray[np.float32]: ...
    def render_qpos(
        self,
        qpos: NDArray[np.float64],
        hidden_geoms: Iterable[int] = (),
        depth: bool = False,
        mocap_pos: NDArray[np.float64] | None = None,
        mocap_quat: NDArray[np.float64] | None = None,
    ) -> NDArray[np.uint8] | NDArray[np.float32]:
        """The frame of the positions ``qpos`` (the model's full ``nq``): what a replay of a
        recorded state draws, identical to the live frame of the same state."""
        if self._renderer is None:
            raise RuntimeError("render() after close()")
        scratch = self._scratch
        scratch.qpos[:] = qpos
        if mocap_pos is not None and self.model.nmocap:
            scratch.mocap_pos[:] = mocap_pos
            scratch.mocap_quat[:] = mocap_quat
        mujoco.mj_kinematics(self.model, scratch)
        mujoco.mj_camlight(self.model, scratch)
        if self._tracking is not None:
            self._tracking.update(self._camera, scratch, self.width / self.height)
        renderer = self._renderer
        renderer.update_scene(scratch, camera=self._camera, scene_option=self._option)
        hidden = set(hidden_geoms)
        if hidden:
            scene = renderer.scene
            for i in range(scene.ngeom):
                geom = scene.geoms[i]
                if geom.objtype == mujoco.mjtObj.mjOBJ_GEOM and geom.objid in hidden:
                    geom.rgba[3] = 0.0
        if depth:
            renderer.enable_depth_rendering()
            try:
                return renderer.render()
            finally:
                renderer.disable_depth_rendering()
        return renderer.render()

    def close(self) -> None:
        """Free the GL context (idempotent)."""
        renderer, self._renderer = self._renderer, None
        if renderer is not None:
            renderer.close()
        _LIVE.discard(self)

    def __enter__(self) -> FrameRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
