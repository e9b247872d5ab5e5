"""MountainCar's camera: the picture depends on ``x`` alone, so ``x`` is snapped to a grid of
``render_quantum`` (0.003, one pixel) and each cell rendered once (about 2 ms)."""

from __future__ import annotations

import math
from typing import Any

from vlmrl_cli.frames.render import Frame
from vlmrl_cli.shaping.camera import CellCamera, FrameView
from vlmrl_cli.tasks.mountain_car.geometry import MAX_POSITION, MIN_POSITION
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer


class Camera(CellCamera[int]):
    """Renders MountainCar at a position snapped to ``render_quantum``; memoises per grid cell
    (``pixel_cache``: frames whose pixels are kept, about 0.7 MB each).
    """

    def __init__(self, render_quantum: float = 0.003, pixel_cache: int = 384, env_id: str = "MountainCar-v0") -> None:
        if not (math.isfinite(render_quantum) and 0 < render_quantum <= MAX_POSITION - MIN_POSITION):
            raise ValueError(
                f"render_quantum must be in (0, {MAX_POSITION - MIN_POSITION}] x units, got {render_quantum}"
            )
        super().__init__(pixel_cache)
        self.render_quantum = float(render_quantum)
        self.env_id = env_id  # whose renderer draws the track (MountainCarContinuous-v0: flag at 0.45)
        self._renderer: FrameRenderer | None = None
        self._last = round((MAX_POSITION - MIN_POSITION) / self.render_quantum)  # the last grid cell

    def _cell(self, x: float) -> int:
        if not math.isfinite(x):
            raise ValueError(f"x must be finite, got {x}")
        return min(max(round((x - MIN_POSITION) / self.render_quantum), 0), self._last)

    def _cell_position(self, cell: int) -> float:
        return min(max(MIN_POSITION + cell * self.render_quantum, MIN_POSITION), MAX_POSITION)

    def grid_positions(self) -> list[float]:
        """Every position the camera can show (one per grid cell, track end to track end)."""
        return [self._cell_position(cell) for cell in range(self._last + 1)]

    def rendered_position(self, x: float) -> float:
        """The position (x units) whose frame ``view(x)`` shows: ``x`` snapped to the grid."""
        return self._cell_position(self._cell(float(x)))

    def _draw(self, cell: int, sha256: str | None) -> Frame:
        if self._renderer is None:
            self._renderer = FrameRenderer(self.env_id)
        return self._renderer.render(self._cell_position(cell), sha256=sha256)

    def view(self, x: float) -> FrameView:
        """The view of the car at position ``x`` (x units), rendered at most once per grid cell."""
        return self._view_of(self._cell(float(x)))

    def look(self, sim: Any) -> FrameView:
        """The view of the simulator ``sim`` (the unwrapped env): its position ``state[0]``."""
        cell = self._cell(float(sim.state[0]))
        view = self._views.get(cell)  # every env step: a known cell is one dict lookup
        return view if view is not None else self._view_of(cell)
