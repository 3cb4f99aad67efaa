"""Record an episode and write it to mp4, offscreen (docs/DESIGN.md §6).

The episode is recorded at the video rate (``wip_gym.recording``) and rendered afterwards
(``wip_gym.replay``), so rendering never runs inside the control loop.

    python -m wip_gym.video --env wip_gym/KrangTray-v0 --seconds 2 --out krang.mp4
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

import wip_gym  # noqa: F401  (registers the environments, sets MUJOCO_GL)
from wip_gym.camera import COMPUTED_CAMERAS
from wip_gym.envs.base import wip_env
from wip_gym.recording import DEFAULT_FPS, EpisodeRecorder, frame_interval
from wip_gym.replay import DEFAULT_SIZE, open_video, parse_size, render_video

if TYPE_CHECKING:  # the one protocol; wip_gym does not import controllers at run time
    from controllers.policy import Policy

__all__ = ["frame_interval", "open_video", "record_episode"]


def record_episode(
    env: gym.Env,
    path: str | Path,
    policy: Policy | None = None,
    *,
    seconds: float | None = None,
    seed: int | None = None,
    fps: float = DEFAULT_FPS,
    size: tuple[int, int] | None = None,
    camera: str = "follow",
    overlay: bool = True,
    label: str = "",
) -> dict[str, Any]:
    """Run one episode of ``env`` under ``policy`` (zero torques if None), recording it at
    ``fps``, then write it as an mp4 (``size`` default: the env's width x height) through
    ``camera``. Stops at termination, truncation or after ``seconds``. The recording is saved
    beside the video (``.npz``, for ``wip-bench render``). Returns the last ``info`` with
    ``frames`` and ``steps`` added."""
    base = wip_env(env)
    dt = base.dt
    max_steps = None if seconds is None else int(round(seconds / dt))
    recorder = EpisodeRecorder(fps=fps, label=label)
    obs, info = env.reset(seed=seed)
    recorder.on_reset(env, info)
    if policy is not None and hasattr(policy, "reset"):
        policy.reset(obs, info)
    zero = np.zeros(base.action_space.shape)
    steps = 0
    while max_steps is None or steps < max_steps:
        action = zero if policy is None else policy(obs)
        obs, _, terminated, truncated, info = env.step(action)
        recorder.on_step(env, info, steps)
        steps += 1
        if terminated or truncated:
            break
    path = Path(path)
    recording = recorder.recording()
    recording.save(path.with_suffix(".npz"))
    size = size or (
        getattr(base, "width", DEFAULT_SIZE[0]),
        getattr(base, "height", DEFAULT_SIZE[1]),
    )
    frames = render_video(recording, path, size=size, camera=camera, overlay=overlay)
    return {**info, "frames": frames, "steps": steps}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="wip_gym/KrangTray-v0", choices=list(wip_gym.ENV_IDS))
    parser.add_argument("--out", default="out/episode.mp4")
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--size", default="480x320", metavar="WxH")
    parser.add_argument("--fps", type=float, default=DEFAULT_FPS)
    parser.add_argument("--camera", default="follow", help=f"{list(COMPUTED_CAMERAS)} or MJCF")
    args = parser.parse_args(argv)
    env = gym.make(args.env)
    result = record_episode(
        env,
        args.out,
        seconds=args.seconds,
        seed=args.seed,
        fps=args.fps,
        size=parse_size(args.size),
        camera=args.camera,
        label="zero torques",
    )
    env.close()
    print(f"wrote {args.out}: {result['frames']} frames, {result['steps']} steps (zero torques)")


if __name__ == "__main__":
    main()
