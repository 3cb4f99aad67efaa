"""What a video frame costs, setting by setting (the measurement behind ``wip_gym.renderer.FAST``).

    MUJOCO_GL=egl python -m benchmarks.speed.render_cost --env PlanarTray-v0 --size 480x320
    --frames 60

Prints the median wall time per frame (ms) of: the fast settings (no shadows, no reflections,
no anti-aliasing), each expensive setting added alone, all of them, the overlay, and the H.264
encoding of a frame; and the mean absolute pixel difference of each setting to the fast frame
(0-255), i.e. what it changes to the eye.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import tempfile
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from benchmarks.scenario import resolve_env_id
from wip_gym.overlay import OverlayValues, draw_overlay
from wip_gym.renderer import FAST, FrameRenderer, RenderSettings
from wip_gym.replay import open_video, parse_size

VARIANTS: dict[str, RenderSettings] = {
    "fast (chosen)": FAST,
    "+ shadows": dataclasses.replace(FAST, shadows=True),
    "+ anti-aliasing x4": dataclasses.replace(FAST, offsamples=4),
    "+ reflections": dataclasses.replace(FAST, reflections=True),
    "all three": RenderSettings(shadows=True, reflections=True, offsamples=4),
}


def _median_ms(samples: list[float]) -> float:
    return float(np.median(samples) * 1e3)


def measure(env_id: str, size: tuple[int, int], frames: int) -> dict[str, Any]:
    env = gym.make(env_id)
    env.reset(seed=0)
    model, data = env.unwrapped.model, env.unwrapped.data
    results: dict[str, Any] = {"env": env_id, "size": list(size), "frames": frames}
    reference = None
    for name, settings in VARIANTS.items():
        with FrameRenderer(model, *size, settings=settings) as renderer:
            for _ in range(3):
                image = renderer.render(data)
            samples = []
            for _ in range(frames):
                start = time.perf_counter()
                image = renderer.render(data)
                samples.append(time.perf_counter() - start)
        if reference is None:
            reference = image.astype(int)
        results[name] = {
            "ms": _median_ms(samples),
            "mean_abs_diff": float(np.abs(image.astype(int) - reference).mean()),
        }
    values = OverlayValues(3.2, 1.1, 2.5, 0.4, label="unified")
    samples = []
    for _ in range(frames):
        start = time.perf_counter()
        draw_overlay(reference.astype(np.uint8), values)
        samples.append(time.perf_counter() - start)
    results["overlay"] = {"ms": _median_ms(samples)}
    with tempfile.TemporaryDirectory() as tmp:
        frame = reference.astype(np.uint8)
        start = time.perf_counter()
        with open_video(Path(tmp) / "x.mp4", 30, frame) as writer:
            for i in range(frames):
                writer.append_data(np.roll(frame, i, axis=1))
        results["h264 encode"] = {"ms": (time.perf_counter() - start) / (frames + 1) * 1e3}
    env.close()
    return results


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="wip_gym/PlanarTray-v0")
    parser.add_argument("--size", default="480x320", metavar="WxH")
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--json", help="also write the results here")
    args = parser.parse_args(argv)
    results = measure(resolve_env_id(args.env), parse_size(args.size), args.frames)
    for name, value in results.items():
        if isinstance(value, dict):
            diff = value.get("mean_abs_diff")
            extra = "" if diff is None else f"   mean |pixel diff| to fast {diff:5.2f}"
            print(f"{name:<22}{value['ms']:8.1f} ms/frame{extra}")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
