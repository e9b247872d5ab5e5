"""Headless MountainCar-v0 frames at any chosen state, drawn by gymnasium's own renderer."""

from __future__ import annotations

from typing import Any

import numpy as np

from vlmrl_cli.frames.render import Frame
from vlmrl_cli.tasks.mountain_car.geometry import MAX_POSITION, MAX_SPEED, MIN_POSITION


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
