"""The numbers a comparison is about, drawn on a frame (Pillow).

Top left: the label (the controller's name), the time, the distance to the goal and the tray's
tilt. Bottom: the cup's friction use (tangential / (mu normal) tray-cup force, 1 = sliding;
``docs/DESIGN.md §6``) as a bar that is green at 0, yellow near 1 and red from 1 on, with its
value. From the moment the cup is lost, a red banner says when.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw, ImageFont

SLIP = 1.0  # friction use at which the cup slides: the bar turns red
BAR_FULL_SCALE = 1.2  # the bar's right end (a little beyond sliding, so 1 is visibly marked)


@dataclass(frozen=True)
class OverlayValues:
    """One frame's numbers (None: not in this task, e.g. no tray).

    Attributes:
        time: simulated time (s).
        goal_distance: the axle's distance to the goal (m).
        tray_tilt_deg: angle between the tray's normal and world z.
        friction_use: the cup's friction use (1 = sliding).
        cup_lost: the cup has left the tray (now or earlier).
        cup_lost_at: when it left (s), if known.
        label: the panel's name (the controller), or empty.
    """

    time: float
    goal_distance: float
    tray_tilt_deg: float | None = None
    friction_use: float | None = None
    cup_lost: bool = False
    cup_lost_at: float | None = None
    label: str = ""


@lru_cache(maxsize=8)
def _font(size: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    return ImageFont.load_default(size=size)


def bar_colour(use: float) -> tuple[int, int, int]:
    """Green at 0, yellow at 0.75, red from ``SLIP`` on."""
    if not math.isfinite(use) or use >= SLIP:
        return (220, 30, 30)
    u = max(use, 0.0) / SLIP
    if u < 0.75:
        return (int(60 + 180 * u / 0.75), 190, 60)
    return (240, int(190 - 120 * (u - 0.75) / 0.25), 40)


def _shade(frame: NDArray[np.uint8], box: tuple[int, int, int, int]) -> None:
    """Darken a box of the frame in place (a translucent panel for the text)."""
    x0, y0, x1, y1 = box
    region = frame[max(y0, 0) : y1, max(x0, 0) : x1]
    region[:] = (region.astype(np.uint16) * 2 // 5).astype(np.uint8)


def draw_overlay(frame: NDArray[np.uint8], values: OverlayValues) -> NDArray[np.uint8]:
    """A copy of ``frame`` (H x W x 3 uint8) with ``values`` drawn on it."""
    out = np.array(frame, dtype=np.uint8, copy=True)
    height, width = out.shape[:2]
    size = max(9, height // 20)
    pad = max(2, size // 3)
    lines: list[tuple[str, int]] = []  # (text, font size): the label larger
    if values.label:
        lines.append((values.label, size + size // 3))
    lines.append((f"t {values.time:5.2f} s   goal {values.goal_distance:4.2f} m", size))
    if values.tray_tilt_deg is not None:
        lines.append((f"tray tilt {values.tray_tilt_deg:4.1f} deg", size))
    tops = np.cumsum([pad] + [h + pad for _, h in lines]).tolist()
    text_w = int(max(_font(h).getlength(text) for text, h in lines)) + 2 * pad
    _shade(out, (0, 0, text_w, tops[-1]))
    bar_h = size + 2 * pad
    if values.friction_use is not None:
        _shade(out, (0, height - bar_h, width, height))
    lost_text = None
    if values.cup_lost:
        when = "" if values.cup_lost_at is None else f" at {values.cup_lost_at:.2f} s"
        lost_text = f"CUP LOST{when}"
    image = Image.fromarray(out)
    draw = ImageDraw.Draw(image)
    for (text, h), top in zip(lines, tops, strict=False):
        draw.text((pad, top), text, fill=(255, 255, 255), font=_font(h))
    if values.friction_use is not None:
        use = values.friction_use
        caption = f"cup friction use {use:4.2f}"
        caption_w = int(_font(size).getlength("cup friction use 0.00")) + 2 * pad
        x0, x1 = caption_w, width - pad
        y0, y1 = height - bar_h + pad, height - pad
        draw.text((pad, y0 - 1), caption, fill=(255, 255, 255), font=_font(size))
        draw.rectangle((x0, y0, x1, y1), outline=(200, 200, 200))
        filled = min(max(use, 0.0), BAR_FULL_SCALE) / BAR_FULL_SCALE if math.isfinite(use) else 1
        if filled > 0:
            draw.rectangle((x0, y0, x0 + int(filled * (x1 - x0)), y1), fill=bar_colour(use))
        x_slip = x0 + int(SLIP / BAR_FULL_SCALE * (x1 - x0))
        draw.line((x_slip, y0 - 2, x_slip, y1 + 2), fill=(255, 255, 255), width=2)
    if lost_text is not None:
        font = _font(size + 2)
        text_w = int(font.getlength(lost_text)) + 2 * pad
        x = width - text_w - pad
        draw.rectangle((x, pad, x + text_w, pad + size + 2 * pad), fill=(200, 20, 20))
        draw.text((x + pad, pad + pad // 2), lost_text, fill=(255, 255, 255), font=font)
    return np.asarray(image)
