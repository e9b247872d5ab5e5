"""One rendered RGB frame and its digest: what every camera draws and every VLM backend reads."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Frame:
    """One RGB frame, shape (H, W, 3) uint8, and the SHA-256 of its bytes.

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
