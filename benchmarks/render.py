"""Videos of a ``wip-bench`` run, rendered from its recordings (``wip_gym.recording``).

``wip-bench compare --video`` records each controller's first episode at the video rate
(``recording_<controller>.npz`` in the output directory) and hands the recording to a
rendering process while the next episode runs, so rendering neither touches control timing nor
waits for the whole run. ``wip-bench render DIR`` draws a recorded run again (another camera,
size or rate) without simulating:

    wip-bench render out/demo --camera tray --size 640x480 --fps 25

Outputs: ``video_<controller>.mp4`` (``--video each``), ``video_grid.mp4`` with every
controller side by side in sync (``--video grid``), or both (``--video both``). ``wip-bench
render``'s are named by what they show, ``video_<controller>.<camera>-<W>x<H>-<fps>fps.mp4``
and ``video_grid.<camera>-<W>x<H>-<fps>fps.mp4`` (:func:`rendering_tag`): new files beside the
run's videos, never over them (a render with the same camera, size and rate replaces its own).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import time
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import imageio.v2 as imageio

from wip_gym.camera import camera_names
from wip_gym.recording import DEFAULT_FPS, Recording
from wip_gym.replay import DEFAULT_SIZE, grid_still, parse_size, render_grid, render_video

VIDEO_KINDS = ("each", "grid", "both")
GRID_FILE = "video_grid.mp4"


def recording_file(out: Path, controller: str) -> Path:
    return out / f"recording_{controller}.npz"


def video_file(out: Path, controller: str, tag: str | None = None) -> Path:
    """A controller's video: ``video_<controller>.mp4`` (compare's), or with ``tag``
    (``wip-bench render``'s) ``video_<controller>.<tag>.mp4``."""
    return out / f"video_{controller}{'.' + tag if tag else ''}.mp4"


def grid_file(out: Path, tag: str | None = None) -> Path:
    """The grid: :data:`GRID_FILE`, or with ``tag`` ``video_grid.<tag>.mp4``."""
    return out / (GRID_FILE if not tag else f"video_grid.{tag}.mp4")


@dataclass(frozen=True)
class VideoOptions:
    """What to render: ``kind`` (``each``: one mp4 per controller, ``grid``: all side by side,
    ``both``), the frame ``size`` (width, height; per panel in the grid), ``fps``, ``camera``."""

    kind: str = "each"
    size: tuple[int, int] = DEFAULT_SIZE
    fps: float = DEFAULT_FPS
    camera: str = "follow"

    def __post_init__(self) -> None:
        if self.kind not in VIDEO_KINDS:
            raise ValueError(f"--video must be one of {list(VIDEO_KINDS)}, got {self.kind!r}")
        if not self.fps > 0:
            raise ValueError(f"--fps must be positive, got {self.fps}")

    @property
    def tag(self) -> str:
        """What the videos show, for their names: ``<camera>-<W>x<H>-<fps>fps``."""
        return f"{self.camera}-{self.size[0]}x{self.size[1]}-{self.fps:g}fps"

    @property
    def each(self) -> bool:
        return self.kind in ("each", "both")

    @property
    def grid(self) -> bool:
        return self.kind in ("grid", "both")


def add_video_arguments(parser: argparse.ArgumentParser, default_kind: str | None) -> None:
    """``--video [KIND]``, ``--fps``, ``--size WxH``, ``--camera NAME``."""
    parser.add_argument(
        "--video",
        nargs="?",
        const="each",
        default=default_kind,
        choices=VIDEO_KINDS,
        help="each: an mp4 per controller (the default with a bare --video); grid: "
        f"{GRID_FILE}, every controller side by side; both",
    )
    parser.add_argument(
        "--fps",
        type=float,
        help=f"video frame rate (compare: {DEFAULT_FPS:g}, also the recording's; render: the "
        "recording's or lower)",
    )
    parser.add_argument(
        "--size", default="x".join(map(str, DEFAULT_SIZE)), metavar="WxH", help="per panel, even"
    )
    parser.add_argument(
        "--camera", default="follow", help="follow (the robot from its side), tray, or MJCF"
    )


def video_options(
    args: argparse.Namespace, model: Any, default_fps: float = DEFAULT_FPS
) -> VideoOptions | None:
    """The video flags checked against the scenario's ``model`` (None without ``--video``)."""
    if args.video is None:
        return None
    fps = default_fps if args.fps is None else args.fps
    valid = camera_names(model)
    if args.camera not in valid:
        raise ValueError(f"unknown --camera {args.camera!r}; valid: {valid}")
    return VideoOptions(args.video, parse_size(args.size), fps, args.camera)


def _start_worker() -> None:
    """(In a rendering process, first.) One llvmpipe thread per rendering process unless the
    user set ``LP_NUM_THREADS``: the other core runs the control loop. Read by Mesa when the
    first GL context is made, i.e. here, before any frame."""
    os.environ.setdefault("LP_NUM_THREADS", "1")


def _warm_up() -> float:
    """(In a rendering process.) Import the rendering stack and make a GL context while the
    first episode runs, so the first video does not wait for them."""
    start = time.perf_counter()
    import mujoco

    from wip_gym.renderer import FrameRenderer

    xml = "<mujoco><worldbody><camera name='warm_up'/></worldbody></mujoco>"
    FrameRenderer(mujoco.MjModel.from_xml_string(xml), 16, 16, camera="warm_up").close()
    return time.perf_counter() - start


def _render_one(recording_path: str, video_path: str, options: VideoOptions) -> float:
    """(In a rendering process.) One controller's video; returns its wall time (s)."""
    start = time.perf_counter()
    recording = Recording.load(recording_path)
    render_video(recording, video_path, size=options.size, fps=options.fps, camera=options.camera)
    return time.perf_counter() - start


def _render_grid(
    recording_paths: list[str],
    grid_path: str,
    options: VideoOptions,
    panels: list[str | None],
    also_write: list[str | None],
) -> float:
    start = time.perf_counter()
    recordings = [Recording.load(p) for p in recording_paths]
    layout = render_grid(
        recordings,
        grid_path,
        size=options.size,
        fps=options.fps,
        camera=options.camera,
        panel_videos=panels,
        also_write=also_write,
    )
    Path(grid_path).with_suffix(".json").write_text(json.dumps(layout, indent=2) + "\n")
    return time.perf_counter() - start


class VideoJobs:
    """Renders a run's videos in one background process (spawned: JAX and EGL do not survive
    a fork), one controller as soon as its recording is saved.

    Use: ``submit(controller)`` after saving ``recording_file(out, controller)``; ``finish(
    controllers)`` waits, renders the grid and returns ``{"videos": [...], ...}``. With both
    kinds, the last of ``controllers`` is drawn once, into its video and the grid together.
    ``workers``: rendering processes (0: render in this process, e.g. on a single core).
    ``tag``: in the videos' names (:func:`video_file`; ``wip-bench render``'s).
    """

    def __init__(
        self,
        out: Path,
        options: VideoOptions,
        workers: int = 1,
        controllers: list[str] | None = None,
        tag: str | None = None,
    ) -> None:
        self.out = Path(out)
        self.options = options
        self.tag = tag
        both = options.each and options.grid
        self._with_grid = controllers[-1] if (both and controllers) else None
        self._pool: ProcessPoolExecutor | None = None
        if workers > 0:
            self._pool = ProcessPoolExecutor(
                max_workers=workers,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=_start_worker,
            )
        self._futures: list[Future[float]] = []
        self._seconds: list[float] = []
        self._started = time.perf_counter()
        if self._pool is not None:
            self._futures.append(self._pool.submit(_warm_up))

    def _run(self, function: Any, *args: Any) -> None:
        if self._pool is None:
            self._seconds.append(function(*args))
        else:
            self._futures.append(self._pool.submit(function, *args))

    def submit(self, controller: str) -> None:
        """Render ``controller``'s video now (if ``each``; the last one with the grid)."""
        if self.options.each and controller != self._with_grid:
            self._run(
                _render_one,
                str(recording_file(self.out, controller)),
                str(video_file(self.out, controller, self.tag)),
                self.options,
            )

    def finish(self, controllers: list[str]) -> dict[str, Any]:
        """Wait for the videos, then render the grid; the paths and the rendering time."""
        try:
            for future in self._futures:
                self._seconds.append(future.result())
            self._futures = []
            tag = self.tag
            videos = (
                [str(video_file(self.out, c, tag)) for c in controllers]
                if self.options.each
                else []
            )
            if self.options.grid:
                # panels decoded from the controllers' videos when they exist: not drawn twice
                each, last = self.options.each, self._with_grid
                panels = [
                    str(video_file(self.out, c, tag)) if each and c != last else None
                    for c in controllers
                ]
                own = [
                    str(video_file(self.out, c, tag)) if c == last else None for c in controllers
                ]
                recordings = [str(recording_file(self.out, c)) for c in controllers]
                grid = str(grid_file(self.out, tag))
                self._run(_render_grid, recordings, grid, self.options, panels, own)
                for future in self._futures:
                    self._seconds.append(future.result())
                videos.append(grid)
        finally:
            self.close()
        return {
            "videos": videos,
            "render_process_s": float(sum(self._seconds)),
            "wall_since_start_s": time.perf_counter() - self._started,
        }

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


# ------------------------------------------------------------------ wip-bench render
def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dir", help="a wip-bench compare output directory (recording_*.npz)")
    add_video_arguments(parser, default_kind="both")
    parser.add_argument("--out", help="where to write the videos (default: DIR)")
    parser.add_argument(
        "--still",
        metavar="PNG",
        help="instead of videos: one grid frame, lossless, as a PNG (e.g. a README figure)",
    )
    parser.add_argument(
        "--at", type=float, default=0.0, metavar="SECONDS", help="the --still frame's time"
    )


def recorded_controllers(directory: Path) -> list[str]:
    """The controllers recorded in ``directory``: in ``summary.json``'s order when there is
    one, else by name."""
    found = {p.name[len("recording_") : -len(".npz")] for p in directory.glob("recording_*.npz")}
    if not found:
        raise ValueError(f"no recording_*.npz in {directory}: run wip-bench compare --video")
    summary = directory / "summary.json"
    if summary.exists():
        order = list(json.loads(summary.read_text()).get("controllers", {}))
        return [c for c in order if c in found] + sorted(found - set(order))
    return sorted(found)


def run(args: argparse.Namespace) -> dict[str, Any]:
    directory = Path(args.dir)
    controllers = recorded_controllers(directory)
    first = Recording.load(recording_file(directory, controllers[0]))
    import gymnasium as gym

    env = gym.make(first.env_id, **first.env_kwargs)
    try:
        options = video_options(args, env.unwrapped.model, first.fps)
    finally:
        env.close()
    assert options is not None
    if args.still:
        recordings = [Recording.load(recording_file(directory, c)) for c in controllers]
        image = grid_still(recordings, args.at, size=options.size, camera=options.camera)
        Path(args.still).parent.mkdir(parents=True, exist_ok=True)
        imageio.imwrite(args.still, image)
        print(f"still: {args.still} ({image.shape[1]}x{image.shape[0]}, t = {args.at:g} s)")
        return {"still": args.still}
    out = Path(args.out) if args.out else directory
    out.mkdir(parents=True, exist_ok=True)
    if out != directory:
        for c in controllers:  # the grid and a later render find them beside the videos
            target = recording_file(out, c)
            target.write_bytes(recording_file(directory, c).read_bytes())
    cores = os.cpu_count() or 1
    workers = min(cores, len(controllers)) if cores > 1 and options.each else 0
    jobs = VideoJobs(out, options, workers=workers, controllers=controllers, tag=options.tag)
    for c in controllers:
        jobs.submit(c)
    result = jobs.finish(controllers)
    for video in result["videos"]:
        print(f"video: {video}")
    print(f"rendered in {result['wall_since_start_s']:.1f} s")
    return result
