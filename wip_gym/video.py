"""Record an episode to mp4, offscreen (DESIGN 6).

Frames are decimated to ``fps`` (a frame every ``round(1 / (fps dt))`` steps) and rendered at
480 x 320 by default: software rendering makes every frame count.

    python -m wip_gym.video --env wip_gym/KrangTray-v0 --seconds 2 --out krang.mp4
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import imageio.v2 as imageio
import numpy as np

import wip_gym  # noqa: F401  (registers the environments, sets MUJOCO_GL)

if TYPE_CHECKING:  # the one protocol; wip_gym does not import controllers at run time
    from controllers.policy import Policy


def open_video(path: str | Path, fps: float, first_frame: np.ndarray) -> Any:
    """An imageio mp4 writer (H.264) with its first frame written.

    imageio-ffmpeg starts ffmpeg with ``subprocess`` (fork + exec), which JAX warns about once
    JAX has started threads; the child execs ffmpeg at once, so the warning is silenced here.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    writer = imageio.get_writer(path, fps=fps, codec="libx264", quality=7, macro_block_size=16)
    with warnings.catch_warnings():
        warnings.filterwarnings(
            "ignore", message=r"os\.fork\(\) was called", category=RuntimeWarning
        )
        writer.append_data(first_frame)
    return writer


def frame_interval(dt: float, fps: float) -> int:
    """Steps between two video frames: ``round(1 / (fps dt))``, at least 1."""
    if dt <= 0 or fps <= 0:
        raise ValueError(f"dt and fps must be positive, got dt={dt}, fps={fps}")
    return max(1, int(round(1.0 / (fps * dt))))


def record_episode(
    env: gym.Env,
    path: str | Path,
    policy: Policy | None = None,
    *,
    seconds: float | None = None,
    seed: int | None = None,
    fps: float = 30.0,
) -> dict[str, Any]:
    """Run one episode of ``env`` (made with ``render_mode="rgb_array"``) under ``policy``
    (zero torques if None) and write an mp4 at ``fps``. Stops at termination, truncation or
    after ``seconds``. Returns the last ``info`` with ``frames`` and ``steps`` added."""
    if env.render_mode != "rgb_array":
        raise ValueError("record_episode needs an env made with render_mode='rgb_array'")
    dt = env.unwrapped.dt
    every = frame_interval(dt, fps)
    max_steps = None if seconds is None else int(round(seconds / dt))
    obs, info = env.reset(seed=seed)
    if policy is not None and hasattr(policy, "reset"):
        policy.reset(obs, info)
    zero = np.zeros(env.action_space.shape)
    frames = 0
    steps = 0
    with open_video(path, fps, env.render()) as out:
        frames += 1
        while max_steps is None or steps < max_steps:
            action = zero if policy is None else policy(obs)
            obs, _, terminated, truncated, info = env.step(action)
            steps += 1
            if steps % every == 0:
                out.append_data(env.render())
                frames += 1
            if terminated or truncated:
                break
    return {**info, "frames": frames, "steps": steps}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="wip_gym/KrangTray-v0", choices=list(wip_gym.ENV_IDS))
    parser.add_argument("--out", default="out/episode.mp4")
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--width", type=int, default=480)
    parser.add_argument("--height", type=int, default=320)
    args = parser.parse_args(argv)
    env = gym.make(args.env, render_mode="rgb_array", width=args.width, height=args.height)
    result = record_episode(env, args.out, seconds=args.seconds, seed=args.seed)
    print(f"wrote {args.out}: {result['frames']} frames, {result['steps']} steps (zero torques)")


if __name__ == "__main__":
    main()
