"""The simulator's camera: the only component of the visual pipeline that knows the state.

MountainCar's picture depends on the position ``x`` alone, so the camera snaps ``x`` to a
grid of ``render_quantum`` (0.001 x units, a third of a pixel), renders each grid cell once
with gymnasium's own renderer and memoises the cell's SHA-256 and features. Pixels are kept
in a small LRU and re-rendered on demand (a render costs about 2 ms). Everything downstream
(features, VLM, RBF, lock) receives a ``FrameView`` that carries no state: this is the
modality separation of paper Section 3.3.
"""

from __future__ import annotations

import functools
import math
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from vlmrl_cli.frames.geometry import MAX_POSITION, MIN_POSITION
from vlmrl_cli.frames.render import Frame, FrameRenderer
from vlmrl_cli.shaping.features import darkness_counts


@dataclass(frozen=True, eq=False)
class FrameView:
    """What the camera shows: a frame's ``key`` (SHA-256 of its pixels), its ``features``
    ((D,) int64 exact darkness counts, see ``darkness_counts``; divide by ``FEATURE_UNIT`` for
    the [0, 1] features) and the frame itself, loaded lazily by ``frame()``.
    """

    key: str
    features: np.ndarray = field(repr=False)
    _load: Callable[[], Frame] = field(repr=False)

    def frame(self) -> Frame:
        """The full frame (rendered again if the camera's pixel cache dropped it)."""
        return self._load()

    @classmethod
    def of_frame(cls, frame: Frame) -> FrameView:
        """A view of an already rendered frame (e.g. from ``FrameRenderer``)."""
        return cls(key=frame.sha256, features=darkness_counts(frame.pixels), _load=lambda: frame)


class Camera:
    """Renders MountainCar at a position snapped to ``render_quantum``; memoises per grid cell.

    ``renders`` counts calls to gymnasium's renderer; ``pixel_cache`` is how many frames'
    pixels are kept (about 0.7 MB each).

    Example:
        >>> cam = Camera(render_quantum=0.001)
        >>> a, b = cam.view(-0.5), cam.view(-0.50001)  # the same grid cell
        >>> a.key == b.key, cam.renders, a.features.shape
        (True, 1, (600,))
        >>> a.frame().pixels.shape
        (400, 600, 3)
        >>> cam.close()
    """

    def __init__(self, render_quantum: float = 0.003, pixel_cache: int = 256) -> None:
        if not (math.isfinite(render_quantum) and 0 < render_quantum <= MAX_POSITION - MIN_POSITION):
            raise ValueError(
                f"render_quantum must be in (0, {MAX_POSITION - MIN_POSITION}] x units, got {render_quantum}"
            )
        if pixel_cache < 1:
            raise ValueError(f"pixel_cache must be >= 1 frame, got {pixel_cache}")
        self.render_quantum = float(render_quantum)
        self.pixel_cache = int(pixel_cache)
        self.renders = 0
        self._renderer: FrameRenderer | None = None
        self._views: dict[int, FrameView] = {}
        self._frames: OrderedDict[int, Frame] = OrderedDict()
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

    def _render(self, cell: int) -> Frame:
        if self._renderer is None:
            self._renderer = FrameRenderer()
        self.renders += 1
        known = self._views.get(cell)
        if known is not None:  # drawn again after the pixel cache dropped it: same pixels, same key
            return self._renderer.render(self._cell_position(cell), sha256=known.key)
        return self._renderer.render(self._cell_position(cell))

    def _frame(self, cell: int) -> Frame:
        frame = self._frames.get(cell)
        if frame is None:
            frame = self._render(cell)
            self._frames[cell] = frame
            if len(self._frames) > self.pixel_cache:
                self._frames.popitem(last=False)
        else:
            self._frames.move_to_end(cell)
        return frame

    def view(self, x: float) -> FrameView:
        """The view of the car at position ``x`` (x units), rendered at most once per grid cell.

        Called every env step, so a known cell costs one dict lookup (the view is built once).
        """
        cell = self._cell(float(x))
        view = self._views.get(cell)
        if view is None:
            frame = self._frame(cell)
            features = darkness_counts(frame.pixels)
            features.setflags(write=False)
            view = FrameView(key=frame.sha256, features=features, _load=functools.partial(self._frame, cell))
            self._views[cell] = view
        return view

    @property
    def cells(self) -> int:
        """How many grid cells have been seen (memoised)."""
        return len(self._views)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        self._frames.clear()
