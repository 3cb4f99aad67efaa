"""Videos rendered from a recording (``wip_gym.recording``), never inside the control loop.

The model is rebuilt from the recorded scenario (``gymnasium.make(env_id, **env_kwargs)``) and
each recorded state is drawn with the same ``FrameRenderer`` the env's ``render()`` uses, so a
replayed frame equals the live frame of the same state. :func:`render_video` writes one
episode; :func:`render_grid` puts several (the controllers of one run) side by side in sync,
one labelled panel each, an episode that ended early holding its last frame.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Generator, Iterator, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import imageio.v2 as imageio
import numpy as np
from numpy.typing import NDArray

import wip_gym  # noqa: F401  (registers the environments)
from wip_gym.envs.base import wip_env
from wip_gym.overlay import OverlayValues, draw_overlay
from wip_gym.recording import Recording
from wip_gym.renderer import FAST, FrameRenderer, RenderSettings, check_size

DEFAULT_SIZE = (480, 320)
#: a stream of RGB frames that owns resources (a decoder, a writer): close it when done
Frames = Generator[NDArray[np.uint8], None, None]
# A state that moved less than this (m or rad, any qpos entry) since the last drawn frame is
# not drawn again: 0.1 mm at the default framing (a 480 x 320 frame spans ~2.5 m) is 1/50 of a
# pixel. Once a controller has arrived, about half the frames of a 25 s episode are such.
STILL_TOLERANCE = 1e-4


def parse_size(text: str) -> tuple[int, int]:
    """``WxH`` (even integers, for H.264) as ``(width, height)``."""
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"bad size {text!r}: expected WxH, e.g. 480x320") from None
    check_size(width, height)
    return width, height


def open_video(path: str | Path, fps: float, first_frame: NDArray[np.uint8]) -> Any:
    """An imageio mp4 writer (H.264, ``veryfast`` preset) with its first frame written; frame
    sizes must be even (no resizing).

    imageio-ffmpeg starts ffmpeg with ``subprocess`` (fork + exec), which JAX warns about once
    JAX has started threads; the child execs ffmpeg at once, so the warning is silenced here.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    check_size(first_frame.shape[1], first_frame.shape[0])
    writer = imageio.get_writer(
        path,
        fps=fps,
        codec="libx264",
        quality=7,
        macro_block_size=2,
        ffmpeg_params=["-preset", "veryfast"],
    )
    with warnings.catch_warnings():
        warnings.filterwarnings(
            "ignore", message=r"os\.fork\(\) was called", category=RuntimeWarning
        )
        writer.append_data(first_frame)
    return writer


def read_frames(path: str | Path) -> Frames:
    """The frames of a video, decoded one at a time (ffmpeg started as in :func:`open_video`)."""
    with warnings.catch_warnings():
        warnings.filterwarnings(
            "ignore", message=r"os\.fork\(\) was called", category=RuntimeWarning
        )
        reader = imageio.get_reader(path)
    try:
        yield from reader.iter_data()
    finally:
        reader.close()


def frame_count(recording: Recording, fps: float) -> int:
    """Frames of the episode's video at ``fps``: one at reset, then one per ``1 / fps`` of the
    episode (``steps * dt`` long)."""
    return 1 + int(math.floor(recording.steps * recording.dt * fps + 1e-6))


def source_index(recording: Recording, fps: float, j: int) -> int:
    """The recorded frame shown as frame ``j`` at ``fps``: the one nearest in time to
    ``j / fps`` (the last one once the episode has ended: it holds)."""
    times = recording.time
    target = times[0] + j / fps
    k = int(np.searchsorted(times, target))
    if k >= len(times):
        return len(times) - 1
    if k > 0 and target - times[k - 1] <= times[k] - target:
        return k - 1
    return k


def overlay_values(recording: Recording, k: int) -> OverlayValues:
    """Frame ``k``'s overlay numbers."""
    t = float(recording.time[k])
    tilt = float(recording.tray_tilt_deg[k])
    use = float(recording.friction_use[k])
    lost_at = recording.cup_lost_at
    lost = not math.isnan(lost_at) and t >= lost_at
    return OverlayValues(
        time=t,
        goal_distance=float(recording.goal_distance[k]),
        tray_tilt_deg=None if math.isnan(tilt) else tilt,
        friction_use=None if math.isnan(use) else use,
        cup_lost=lost,
        cup_lost_at=lost_at if lost else None,
        label=recording.label,
    )


class Replay:
    """Draws a recording's frames on a model rebuilt from its scenario.

    Args:
        recording: what to draw.
        width, height: frame size (even).
        camera: ``follow``, ``tray`` or an MJCF camera (see ``wip_gym.camera``).
        overlay: draw the label and numbers (``wip_gym.overlay``).
        settings: render settings.
        still_tolerance: in :meth:`frames`, the largest change of any ``qpos`` entry (m, rad)
            below which the scene is not drawn again (:data:`STILL_TOLERANCE`; 0: always).
    """

    def __init__(
        self,
        recording: Recording,
        width: int = DEFAULT_SIZE[0],
        height: int = DEFAULT_SIZE[1],
        camera: str = "follow",
        overlay: bool = True,
        settings: RenderSettings = FAST,
        still_tolerance: float = STILL_TOLERANCE,
    ) -> None:
        self.recording = recording
        self.overlay = overlay
        self._env = gym.make(recording.env_id, max_episode_steps=-1, **recording.env_kwargs)
        base = wip_env(self._env)
        base.reset(seed=0)
        model = base.model
        if recording.qpos.shape[1] != model.nq:
            raise ValueError(
                f"recording has nq={recording.qpos.shape[1]}, the rebuilt {recording.env_id} "
                f"model has nq={model.nq}: recorded with another version of the scene"
            )
        model.site_pos[model.site("goal").id, :2] = recording.goal
        self._payload_geoms = [
            g for g in range(model.ngeom) if model.body(model.geom_bodyid[g]).name == "payload"
        ]
        self._renderer = FrameRenderer(model, width, height, camera=camera, settings=settings)
        self.still_tolerance = still_tolerance
        self._scene: NDArray[np.uint8] | None = None
        self._scene_of: int | None = None  # the recorded frame self._scene shows

    def frame(self, k: int, still_from: int | None = None) -> NDArray[np.uint8]:
        """Recorded frame ``k``, drawn. ``still_from``: a frame whose scene (not its overlay)
        is reused when the state has not moved since by more than ``still_tolerance``."""
        rec = self.recording
        if (
            still_from is not None
            and self._scene is not None
            and self._scene_of == still_from
            and rec.payload_visible[k] == rec.payload_visible[still_from]
            and np.abs(rec.qpos[k] - rec.qpos[still_from]).max() <= self.still_tolerance
        ):
            image = self._scene
        else:
            hidden = () if rec.payload_visible[k] else self._payload_geoms
            image = self._renderer.render_qpos(rec.qpos[k], hidden)
            self._scene, self._scene_of = image, k
        if self.overlay:
            image = draw_overlay(image, overlay_values(rec, k))
        return image

    def frames(self, fps: float | None = None, count: int | None = None) -> Frames:
        """The video's frames at ``fps`` (default: the recording's), ``count`` of them (default:
        the episode's; more hold the last frame). A recorded frame is drawn once and repeated
        while it is the one shown; a robot standing still (within ``still_tolerance``) is not
        drawn again, only its overlay."""
        rec = self.recording
        fps = rec.fps if fps is None else fps
        if fps > rec.fps + 1e-9:
            raise ValueError(
                f"fps {fps} is above the recording's {rec.fps}: record at a higher rate"
            )
        count = frame_count(rec, fps) if count is None else count
        last_k = -1  # no frame index: the first iteration draws
        for j in range(count):
            k = source_index(rec, fps, j)
            if k != last_k:
                image = self.frame(k, still_from=self._scene_of)
                last_k = k
            yield image

    def close(self) -> None:
        self._renderer.close()
        self._env.close()

    def __enter__(self) -> Replay:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def render_video(
    recording: Recording,
    path: str | Path,
    *,
    size: tuple[int, int] = DEFAULT_SIZE,
    fps: float | None = None,
    camera: str = "follow",
    overlay: bool = True,
    settings: RenderSettings = FAST,
) -> int:
    """Write ``recording`` as an mp4 at ``fps`` (default: the recording's); returns the number
    of frames written."""
    fps = recording.fps if fps is None else fps
    with Replay(recording, *size, camera=camera, overlay=overlay, settings=settings) as replay:
        frames = replay.frames(fps)
        written = 1
        with open_video(path, fps, next(frames)) as writer:
            for image in frames:
                writer.append_data(image)
                written += 1
    return written


def grid_layout(panels: int) -> tuple[int, int]:
    """``(rows, columns)`` for ``panels`` panels: as square as possible, wider than high."""
    if panels < 1:
        raise ValueError(f"a grid needs at least one panel, got {panels}")
    columns = math.ceil(math.sqrt(panels))
    return math.ceil(panels / columns), columns


def tile(images: Sequence[np.ndarray], rows: int, columns: int) -> NDArray[np.uint8]:
    """Panels (same size) in row-major order; empty cells black."""
    height, width = images[0].shape[:2]
    out = np.zeros((rows * height, columns * width, 3), dtype=np.uint8)
    for i, image in enumerate(images):
        r, c = divmod(i, columns)
        out[r * height : (r + 1) * height, c * width : (c + 1) * width] = image
    return out


def _held(frames: Iterator[NDArray[np.uint8]], count: int) -> Frames:
    """``frames`` cut or padded to ``count`` by holding the last one."""
    produced, last = 0, None
    for image in frames:
        if produced >= count:
            return
        last = image
        produced += 1
        yield image
    if last is None:
        raise ValueError("a grid panel has no frames")
    for _ in range(count - produced):
        yield last


def _tee(frames: Iterator[NDArray[np.uint8]], path: str | Path, fps: float) -> Frames:
    """``frames``, also written to their own video at ``path`` (closed when exhausted or
    closed)."""
    writer = None
    try:
        for image in frames:
            if writer is None:
                writer = open_video(path, fps, image)
            else:
                writer.append_data(image)
            yield image
    finally:
        if writer is not None:
            writer.close()


def render_grid(
    recordings: Sequence[Recording],
    path: str | Path,
    *,
    size: tuple[int, int] = DEFAULT_SIZE,
    fps: float | None = None,
    camera: str = "follow",
    settings: RenderSettings = FAST,
    panel_videos: Sequence[str | Path | None] | None = None,
    also_write: Sequence[str | Path | None] | None = None,
) -> dict[str, Any]:
    """Write the recordings side by side in sync (``size`` per panel, each labelled by its
    recording's label); the video lasts as long as the longest episode, the shorter ones
    holding their last frame.

    ``panel_videos[i]``: recording ``i``'s mp4, already rendered at this ``size``, ``fps`` and
    camera, decoded instead of drawn again (None: drawn). ``also_write[i]``: a drawn panel is
    also written to its own video there, in the same pass (the last controller of a run, whose
    video and the grid would otherwise wait for each other).
    Returns the layout: ``{"frames", "fps", "rows", "columns", "panel_size", "panels"}``."""
    if not recordings:
        raise ValueError("render_grid needs at least one recording")
    n = len(recordings)
    panel_videos = [None] * n if panel_videos is None else list(panel_videos)
    also_write = [None] * n if also_write is None else list(also_write)
    if len(panel_videos) != n or len(also_write) != n:
        raise ValueError(f"panel_videos and also_write must have one entry per recording ({n})")
    fps = recordings[0].fps if fps is None else fps
    rows, columns = grid_layout(n)
    count = max(frame_count(r, fps) for r in recordings)
    replays: list[Replay] = []
    inner: list[Frames] = []
    sources: list[Frames] = []
    try:
        for rec, video, own in zip(recordings, panel_videos, also_write, strict=True):
            if video is not None:
                frames = read_frames(video)
            else:
                replay = Replay(rec, *size, camera=camera, settings=settings)
                replays.append(replay)
                frames = replay.frames(fps)
                if own is not None:
                    frames = _tee(frames, own, fps)
            inner.append(frames)
            sources.append(_held(frames, count))
        first = tile([next(s) for s in sources], rows, columns)
        if first.shape[:2] != (rows * size[1], columns * size[0]):
            raise ValueError(
                f"panel videos are {first.shape[1] // columns}x{first.shape[0] // rows}, "
                f"expected {size[0]}x{size[1]}"
            )
        with open_video(path, fps, first) as writer:
            for _ in range(count - 1):
                writer.append_data(tile([next(s) for s in sources], rows, columns))
    finally:
        for source in sources + inner:
            source.close()  # closes the decoders and the panels' own videos
        for replay in replays:
            replay.close()
    return {
        "frames": count,
        "fps": fps,
        "rows": rows,
        "columns": columns,
        "panel_size": list(size),
        "panels": [r.label for r in recordings],
    }


def grid_still(
    recordings: Sequence[Recording],
    at: float = 0.0,
    *,
    size: tuple[int, int] = DEFAULT_SIZE,
    camera: str = "follow",
    settings: RenderSettings = FAST,
) -> NDArray[np.uint8]:
    """One frame of the grid: every recording at time ``at`` (s; an episode that ended before
    shows its last frame), drawn losslessly (for a figure)."""
    if not recordings:
        raise ValueError("grid_still needs at least one recording")
    if not math.isfinite(at) or at < 0:
        raise ValueError(f"at must be a time >= 0 s, got {at}")
    rows, columns = grid_layout(len(recordings))
    images = []
    for rec in recordings:
        with Replay(rec, *size, camera=camera, settings=settings) as replay:
            images.append(replay.frame(_at(rec, at)))
    return tile(images, rows, columns)


def _at(recording: Recording, at: float) -> int:
    """The recorded frame nearest to time ``at`` (the last one after the end)."""
    return int(np.argmin(np.abs(recording.time - min(at, recording.time[-1]))))
