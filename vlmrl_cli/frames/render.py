"""Headless MountainCar-v0 frames at any chosen state, drawn by gymnasium's own renderer."""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vlmrl_cli.frames.geometry import MAX_POSITION, MAX_SPEED, MIN_POSITION


@dataclass(frozen=True)
class Frame:
    """One RGB frame, shape (400, 600, 3) uint8, and the SHA-256 of its bytes.

    ``frame_id`` is an optional human tag (e.g. ``"x=-0.50"``) used to label tables and to
    match replay transcripts; the simulated VLM never reads it.
    """

    pixels: np.ndarray = field(repr=False)
    sha256: str
    frame_id: str | None = None

    @classmethod
    def from_pixels(cls, pixels: np.ndarray, frame_id: str | None = None) -> Frame:
        pixels = np.ascontiguousarray(pixels, dtype=np.uint8)
        # the buffer itself (C-contiguous: the same bytes as tobytes(), without copying them)
        return cls(pixels=pixels, sha256=hashlib.sha256(pixels.data.cast("B")).hexdigest(),
                   frame_id=frame_id)

    @classmethod
    def drawn(cls, pixels: np.ndarray, frame_id: str | None = None, sha256: str | None = None) -> Frame:
        """A frame a renderer just drew; ``sha256``: its digest when known from an earlier render of
        the same state (a renderer draws it identically), so it is not hashed again."""
        if sha256 is not None:
            return cls(pixels=np.ascontiguousarray(pixels, dtype=np.uint8), sha256=sha256, frame_id=frame_id)
        return cls.from_pixels(pixels, frame_id=frame_id)

    def png_bytes(self) -> bytes:
        """The frame encoded as PNG (what HTTP backends send)."""
        import io

        from PIL import Image

        buf = io.BytesIO()
        Image.fromarray(self.pixels).save(buf, format="PNG")
        return buf.getvalue()


class FrameRenderer:
    """Renders MountainCar-v0 (or ``env_id``, another env of the same track) at arbitrary (x, v)
    with ``render_mode="rgb_array"``.

    Holds one unwrapped gymnasium env; no display is needed.

    Example:
        >>> renderer = FrameRenderer()
        >>> renderer.render(-0.5).pixels.shape
        (400, 600, 3)
        >>> renderer.close()
    """

    def __init__(self, env_id: str = "MountainCar-v0") -> None:
        import gymnasium as gym

        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # harmless for rgb_array, needed by some SDL builds
        # env_id: MountainCar-v0 or MountainCarContinuous-v0 (same track and car, its flag at 0.45)
        self._env: Any = gym.make(env_id, render_mode="rgb_array").unwrapped
        self._env.reset(seed=0)

    def render(self, x: float, velocity: float = 0.0, frame_id: str | None = None,
               sha256: str | None = None) -> Frame:
        """Render the frame of position ``x`` (and ``velocity``, which the picture ignores).

        ``sha256``: the digest of this very frame, known from an earlier render of the same
        position (gymnasium draws it identically), so it is not hashed again.
        """
        if not MIN_POSITION <= x <= MAX_POSITION:
            raise ValueError(f"x={x} is outside the track [{MIN_POSITION}, {MAX_POSITION}]")
        self._env.state = np.array([x, np.clip(velocity, -MAX_SPEED, MAX_SPEED)], dtype=np.float64)
        return Frame.drawn(self._env.render(), frame_id, sha256)

    def close(self) -> None:
        self._env.close()

    def __enter__(self) -> FrameRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
