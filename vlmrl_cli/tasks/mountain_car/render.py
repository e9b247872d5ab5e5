"""Headless MountainCar-v0 frames at any chosen state, drawn by gymnasium's own renderer."""

from __future__ import annotations

import numpy as np

from vlmrl_cli.frames.render import EnvRenderer, Frame
from vlmrl_cli.tasks.mountain_car.geometry import MAX_POSITION, MAX_SPEED, MIN_POSITION


class FrameRenderer(EnvRenderer):
    """Renders MountainCar-v0 (or ``env_id``, another env of the same track) at arbitrary (x, v), headless."""

    def __init__(self, env_id: str = "MountainCar-v0") -> None:
        super().__init__(env_id)  # or MountainCarContinuous-v0 (same track and car, its flag at 0.45)

    def render(self, x: float, velocity: float = 0.0, frame_id: str | None = None,
               sha256: str | None = None) -> Frame:
        """The frame of position ``x`` (``velocity`` is not drawn); ``sha256``: its digest, when known."""
        if not MIN_POSITION <= x <= MAX_POSITION:
            raise ValueError(f"x={x} is outside the track [{MIN_POSITION}, {MAX_POSITION}]")
        return self.draw(np.array([x, np.clip(velocity, -MAX_SPEED, MAX_SPEED)], dtype=np.float64), frame_id, sha256)
