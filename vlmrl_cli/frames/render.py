"""One rendered RGB frame and its digest: what every camera draws and every VLM backend reads."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import Any, Self

import numpy as np


@dataclass(frozen=True)
class Frame:
    """One RGB frame (H, W, 3) uint8 and the SHA-256 of its bytes; ``frame_id``: an optional tag
    (``"x=-0.50"``) for tables and replay transcripts, never read by the simulated VLM."""

    pixels: np.ndarray = field(repr=False)
    sha256: str
    frame_id: str | None = None

    @classmethod
    def from_pixels(cls, pixels: np.ndarray, frame_id: str | None = None, sha256: str | None = None) -> Frame:
        """The frame of ``pixels``; ``sha256``: its digest when known from an earlier render of the same
        state (a renderer draws it identically), so it is not hashed again."""
        pixels = np.ascontiguousarray(pixels, dtype=np.uint8)
        # the buffer itself (C-contiguous: the same bytes as tobytes(), without copying them)
        digest = hashlib.sha256(pixels.data.cast("B")).hexdigest() if sha256 is None else sha256
        return cls(pixels=pixels, sha256=digest, frame_id=frame_id)

    #: A frame a renderer just drew (``from_pixels``).
    drawn = from_pixels

    def png_bytes(self) -> bytes:
        """The frame encoded as PNG (what HTTP backends send)."""
        import io

        from PIL import Image

        buf = io.BytesIO()
        Image.fromarray(self.pixels).save(buf, format="PNG")
        return buf.getvalue()


class EnvRenderer:
    """Draws one unwrapped gymnasium env off screen (``rgb_array``, no display) at states it is given."""

    def __init__(self, env_id: str) -> None:
        import gymnasium as gym

        self._env: Any = gym.make(env_id, render_mode="rgb_array").unwrapped
        self._env.reset(seed=0)

    def draw(self, state: np.ndarray, frame_id: str | None, sha256: str | None) -> Frame:
        """The frame of the simulator's ``state``; ``sha256``: its digest, when known."""
        self._env.state = state
        return Frame.drawn(self._env.render(), frame_id, sha256)

    def close(self) -> None:
        self._env.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
