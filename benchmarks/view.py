"""``wip-bench view``: a controller driving an env, or a recorded episode, in MuJoCo's
interactive viewer (docs/videos.md §6).

    wip-bench view --env PlanarTray-v0 --controller unified [--seed 0] [--duration 25]
                   [--preset paper] [--set KEY=VALUE ...] [--speed 1]
    wip-bench view --replay out/demo/recording_unified.npz [--speed 0.25]
    wip-bench view --replay out/demo --controller decoupled

Live, the episode is the rollout's (``benchmarks.rollout``: the env and the policy as
``wip-bench compare`` makes them, the same seed gives the same episode); the viewer
(``mujoco.viewer.launch_passive``) shows the env's own MjModel and MjData, synchronised once
per frame of the screen's rate (:data:`VIEW_FPS`) of simulated time and paced to ``--speed``
times real time (a controller slower than that is shown as fast as it runs). A replay rebuilds
the model from the recording's scenario and sets each recorded state (``qpos``, ``qvel``, the
time; ``wip_gym.recording``) at the recording's rate. Closing the window ends either; at the
episode's end the window stays until it is closed.

Without a display it stops before anything runs, with what to do instead (GLFW would abort the
process: ``wip_gym.display``).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from benchmarks.overrides import parse_assignment, resolve_run
from benchmarks.presets import add_configuration_arguments
from benchmarks.render import recorded_controllers, recording_file
from benchmarks.rollout import rollout
from benchmarks.scenario import DEFAULT_DURATION_S, parse_controllers, resolve_env_id
from wip_gym.display import NoDisplayError, require_display
from wip_gym.envs.base import wip_env
from wip_gym.recording import Recording

DEFAULT_ENV = "wip_gym/PlanarTray-v0"
DEFAULT_CONTROLLER = "unified"
VIEW_FPS = 60.0  # viewer syncs per second of simulated time (at --speed 1, of the screen's)
#: opens the viewer on a model and data: ``mujoco.viewer.launch_passive`` (tests give a fake)
Launcher = Callable[[mujoco.MjModel, mujoco.MjData], AbstractContextManager[Any]]


class ViewerClosed(Exception):
    """The viewer's window was closed: the episode stops there."""


def launch_passive(model: mujoco.MjModel, data: mujoco.MjData) -> Any:
    """MuJoCo's passive viewer on ``model`` and ``data`` (imported here: it needs a display)."""
    import mujoco.viewer

    return mujoco.viewer.launch_passive(model, data)


class Pace:
    """Holds a loop to ``speed`` times real time: :meth:`wait` until simulated time ``t``
    (s since the start) is due on the wall clock."""

    def __init__(self, speed: float) -> None:
        self.speed = speed
        self.start: float | None = None
        self.t0 = 0.0

    def wait(self, t: float) -> None:
        now = time.perf_counter()
        if self.start is None:
            self.start, self.t0 = now, t
            return
        due = self.start + (t - self.t0) / self.speed
        if due > now:
            time.sleep(due - now)


class LiveView:
    """The rollout's ``on_step`` hook that shows the episode: opens the viewer at the reset
    (step 0) on the env's model and data, then syncs it once per :data:`VIEW_FPS` frame of
    simulated time, paced; :class:`ViewerClosed` when its window is closed."""

    def __init__(self, launch: Launcher, speed: float) -> None:
        self.launch = launch
        self.pace = Pace(speed)
        self.viewer: Any = None
        self._context: AbstractContextManager[Any] | None = None
        self._every = 1
        self.syncs = 0

    def __call__(self, env: gym.Env, info: dict[str, Any], step_index: int) -> None:
        base = wip_env(env)
        if step_index == 0:
            self._context = self.launch(base.model, base.data)
            self.viewer = self._context.__enter__()
            self._every = max(1, int(round(1.0 / (VIEW_FPS * base.dt))))
        elif step_index % self._every:
            return
        if not self.viewer.is_running():
            raise ViewerClosed
        self.pace.wait(float(base.data.time))
        self.viewer.sync()
        self.syncs += 1

    def hold(self) -> None:
        """Leave the last state in the window until it is closed."""
        while self.viewer is not None and self.viewer.is_running():
            time.sleep(0.05)

    def close(self) -> None:
        if self._context is not None:
            self._context.__exit__(None, None, None)
            self._context = self.viewer = None


def replay_states(
    recording: Recording, model: mujoco.MjModel, data: mujoco.MjData
) -> Iterator[int]:
    """Set each recorded frame's state (time, ``qpos``, ``qvel``; the payload shown once it is
    in the hand) into ``data`` with its kinematics (``mj_forward``), yielding the frame's index
    after each."""
    payload = [g for g in range(model.ngeom) if model.body(model.geom_bodyid[g]).name == "payload"]
    alpha = model.geom_rgba[payload, 3].copy()
    for k in range(recording.frames):
        data.time = recording.time[k]
        data.qpos[:] = recording.qpos[k]
        data.qvel[:] = recording.qvel[k]
        model.geom_rgba[payload, 3] = alpha if recording.payload_visible[k] else 0.0
        mujoco.mj_forward(model, data)
        yield k


def replay(recording: Recording, launch: Launcher, speed: float, hold: bool = True) -> int:
    """Show ``recording`` in the viewer at ``speed`` times its rate; the frames shown."""
    env = gym.make(recording.env_id, max_episode_steps=-1, **recording.env_kwargs)
    try:
        base = wip_env(env)
        base.reset(seed=0)
        model, data = base.model, base.data
        if recording.qpos.shape[1] != model.nq:
            raise ValueError(
                f"the recording has nq={recording.qpos.shape[1]}, the rebuilt "
                f"{recording.env_id} model nq={model.nq}: recorded with another scene"
            )
        model.site_pos[model.site("goal").id, :2] = recording.goal
        pace, shown = Pace(speed), 0
        with launch(model, data) as viewer:
            for k in replay_states(recording, model, data):
                if not viewer.is_running():
                    return shown
                pace.wait(float(recording.time[k]))
                viewer.sync()
                shown += 1
            while hold and viewer.is_running():
                time.sleep(0.05)
        return shown
    finally:
        env.close()


# ------------------------------------------------------------------ the command
def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", default=DEFAULT_ENV, help="env id (wip_gym/NAME or NAME)")
    parser.add_argument(
        "--controller",
        default=None,
        help=f"a registered controller ({DEFAULT_CONTROLLER} by default); with --replay DIR, "
        "whose recording",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--duration", type=float, default=DEFAULT_DURATION_S, metavar="SECONDS")
    add_configuration_arguments(
        parser, set_help="env.<argument>, plan.<field> or <controller>.<field.path> (compare's)"
    )
    parser.add_argument(
        "--replay",
        metavar="NPZ_OR_DIR",
        help="show a recording instead: a recording_<controller>.npz, or a compare --video "
        "run's directory (its first controller's, or --controller's)",
    )
    parser.add_argument("--speed", type=float, default=1.0, help="times real time")


def recording_path(replay_arg: str, controller: str | None) -> Path:
    """The recording ``--replay`` names: the file itself, or ``DIR``'s
    ``recording_<controller>.npz`` (its first controller's without ``--controller``)."""
    path = Path(replay_arg)
    if path.is_dir():
        recorded = recorded_controllers(path)
        if controller is None:
            controller = recorded[0]
        if controller not in recorded:
            raise ValueError(f"no recording of {controller!r} in {path}; recorded: {recorded}")
        return recording_file(path, controller)
    if not path.is_file():
        raise ValueError(f"--replay {replay_arg}: no such recording or directory")
    return path


def run(
    args: argparse.Namespace, launch: Launcher = launch_passive, hold: bool = True
) -> dict[str, Any]:
    """Check the arguments (``ValueError``: a usage error, nothing has run), then the display,
    then show the episode or the recording (``hold``: the window stays at the end until it
    is closed)."""
    if not (np.isfinite(args.speed) and args.speed > 0):
        raise ValueError(f"--speed must be positive, got {args.speed}")
    if args.replay is not None:
        recording = Recording.load(recording_path(args.replay, args.controller))
        _display()
        shown = replay(recording, launch, args.speed, hold=hold)
        return {"replayed": recording.label, "frames": shown}
    if not (np.isfinite(args.duration) and args.duration > 0):
        raise ValueError(f"--duration must be positive, got {args.duration}")
    env_id = resolve_env_id(args.env)
    controller = parse_controllers(args.controller or DEFAULT_CONTROLLER)
    if len(controller) != 1:
        raise ValueError(f"--controller takes one controller, got {controller}")
    name = controller[0]
    overrides = dict(parse_assignment(text) for text in args.overrides)
    spec = resolve_run(env_id, [name], args.preset, overrides=overrides)
    _display()
    view = LiveView(launch, args.speed)
    try:
        episode = rollout(
            env_id,
            spec.env_kwargs,
            name,
            spec.configs[name],
            args.seed,
            args.duration,
            on_step=view,
        )
    except ViewerClosed:
        print("the window was closed")
        return {"controller": name, "closed": True, "syncs": view.syncs}
    else:
        metrics = episode.metrics
        print(
            f"{name} on {env_id} (seed {args.seed}): {metrics['outcome']} after "
            f"{metrics['sim_time_s']:.2f} s; close the window to quit"
        )
        if hold:
            view.hold()
        return {"controller": name, "closed": False, "syncs": view.syncs, "metrics": metrics}
    finally:
        view.close()


def _display() -> None:
    """The display check as a usage error of the command (exit status 2 with its message)."""
    try:
        require_display("wip-bench view")
    except NoDisplayError as error:
        raise ValueError(str(error)) from None
