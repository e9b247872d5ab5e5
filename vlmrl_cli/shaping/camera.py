"""The simulator's camera, the only part of the visual pipeline that reads the state (paper Section
3.3): a ``CellCamera`` renders each grid cell once and hands on stateless ``FrameView`` s."""

from __future__ import annotations

import functools
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

import numpy as np

from vlmrl_cli.frames.render import Frame
from vlmrl_cli.shaping.features import darkness_counts

Cell = TypeVar("Cell")  # a camera's grid cell: MountainCar's position index, Acrobot's pair of angle bins


@dataclass(frozen=True, eq=False)
class FrameView:
    """What the camera shows: ``key`` (SHA-256 of the pixels), ``features`` ((D,) int64
    ``darkness_counts``); ``frame()`` draws the frame (again if the camera's pixel cache dropped it),
    ``release()`` drops its pixels from that cache (a deterministic VLM has labelled it)."""

    key: str
    features: np.ndarray = field(repr=False)
    frame: Callable[[], Frame] = field(repr=False)
    release: Callable[[], None] = field(default=lambda: None, repr=False)

    @classmethod
    def of_frame(cls, frame: Frame) -> FrameView:
        """A view of an already rendered frame (e.g. from ``FrameRenderer``)."""
        return cls(key=frame.sha256, features=darkness_counts(frame.pixels), frame=lambda: frame)


class CellCamera(Generic[Cell]):
    """A camera of grid ``Cell`` s: each cell's ``FrameView`` memoised, its pixels in an LRU of
    ``pixel_cache`` frames; a subclass draws a cell (``_draw``, opening ``_renderer`` on demand)."""

    def __init__(self, pixel_cache: int = 256) -> None:
        if pixel_cache < 1:
            raise ValueError(f"pixel_cache must be >= 1 frame, got {pixel_cache}")
        self.pixel_cache = int(pixel_cache)
        self.renders = 0
        self._views: dict[Cell, FrameView] = {}
        self._frames: OrderedDict[Cell, Frame] = OrderedDict()
        self._renderer: Any = None  # what a subclass's ``_draw`` opens on demand; ``_release`` closes it

    def _draw(self, cell: Cell, sha256: str | None) -> Frame:
        raise NotImplementedError

    def _release(self) -> None:
        """Close the renderer (it reopens on demand)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def _frame(self, cell: Cell) -> Frame:
        frame = self._frames.get(cell)
        if frame is None:
            self.renders += 1
            known = self._views.get(cell)  # drawn again after the pixel cache dropped it: the key is known
            frame = self._draw(cell, known.key if known is not None else None)
            self._frames[cell] = frame
            if len(self._frames) > self.pixel_cache:
                self._frames.popitem(last=False)
        else:
            self._frames.move_to_end(cell)
        return frame

    def _drop(self, cell: Cell) -> None:
        self._frames.pop(cell, None)

    def _view_of(self, cell: Cell) -> FrameView:
        """The memoised view of ``cell``: called every env step, so a known cell is a dict lookup."""
        view = self._views.get(cell)
        if view is None:
            frame = self._frame(cell)
            features = darkness_counts(frame.pixels)
            features.setflags(write=False)
            view = FrameView(key=frame.sha256, features=features, frame=functools.partial(self._frame, cell),
                             release=functools.partial(self._drop, cell))
            self._views[cell] = view
        return view

    @property
    def cells(self) -> int:
        """How many grid cells have been seen (memoised)."""
        return len(self._views)

    def close(self) -> None:
        self._release()
        self._frames.clear()
