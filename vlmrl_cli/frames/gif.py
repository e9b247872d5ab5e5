"""Captioned frames and animated GIFs (Pillow only), for watching an episode."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

LINE_PX = 13  # height of one caption line with Pillow's default font
MARGIN_PX = 4
ALERT_RGB = (200, 0, 0)


def captioned(pixels: np.ndarray, lines: Sequence[str], width: int = 300, alert: str | None = None) -> Image.Image:
    """``pixels`` (H, W, 3) scaled to ``width`` px, above a white banner of ``lines`` (and ``alert`` in red).

    Example:
        >>> img = captioned(np.zeros((400, 600, 3), np.uint8), ["step 0"], width=300, alert="SIMULATED VLM")
        >>> img.size
        (300, 234)
    """
    if width < 1:
        raise ValueError(f"width must be at least 1 pixel, got {width}")
    frame = Image.fromarray(np.ascontiguousarray(pixels, dtype=np.uint8))
    height = max(1, round(frame.height * width / frame.width))
    frame = frame.resize((width, height), Image.Resampling.LANCZOS)
    text = [*lines, *([alert] if alert else [])]
    image = Image.new("RGB", (width, height + 2 * MARGIN_PX + LINE_PX * len(text)), "white")
    image.paste(frame, (0, 0))
    draw = ImageDraw.Draw(image)
    font = ImageFont.load_default()
    for i, line in enumerate(text):
        colour = ALERT_RGB if alert and i == len(text) - 1 else (0, 0, 0)
        draw.text((MARGIN_PX, height + MARGIN_PX + i * LINE_PX), line, fill=colour, font=font)
    return image


def write_gif(images: Sequence[Image.Image], path: Path, frame_ms: int = 80, hold_ms: int = 1500) -> None:
    """Write ``images`` as a looping GIF, ``frame_ms`` per frame and ``hold_ms`` on the last; 64-colour
    palettes keep a 100-frame, 300 px episode well under 1 MB."""
    if not images:
        raise ValueError("a GIF needs at least one image")
    frames = [im.convert("RGB").quantize(colors=64) for im in images]
    durations = [frame_ms] * (len(frames) - 1) + [hold_ms]
    frames[0].save(path, format="GIF", save_all=True, append_images=frames[1:], duration=durations, loop=0,
                   optimize=True)
