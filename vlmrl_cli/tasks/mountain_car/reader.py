"""The simulated VLM's eyes on MountainCar: the wheels' exact (128, 128, 128) grey locates the car;
its column, snapped to ``patch_px`` patches as a ViT sees them, maps back to a position."""

from __future__ import annotations

import numpy as np

from vlmrl_cli.tasks.mountain_car import geometry
from vlmrl_cli.tasks.mountain_car.prompts import ZONE_MILESTONES
from vlmrl_cli.vlm.config import SimKnobs
from vlmrl_cli.vlm.prompts import Milestones
from vlmrl_cli.vlm.sim import MODEL_BASE

WHEEL_GREY = 128
# Columns with at least this many wheel-grey pixels are wheel, not anti-aliasing strays.
_MIN_COLUMN_PIXELS = 3
# Even half off-screen one wheel leaves ~8 solid columns; fewer means no car.
_MIN_WHEEL_COLUMNS = 4
REFUSAL = "I'm sorry, but I cannot find a car in this image."
MCQ_FORMATS: tuple[str, ...] = ("{label}", "Choice = {label}", "{label}.", "The car is at {label}.")


def wheel_column(pixels: np.ndarray) -> float | None:
    """Centre column (image px) of the car's wheels in an RGB frame (H, W, 3), or None; only columns
    holding several wheel-grey pixels count (anti-aliasing leaves single strays)."""
    flat = np.ascontiguousarray(pixels).reshape(-1, 3)
    # one channel first (~4x faster than all three), on a contiguous copy of it
    (hits,) = np.nonzero(np.ascontiguousarray(flat[:, 0]) == WHEEL_GREY)
    grey = (flat[hits, 1] == WHEEL_GREY) & (flat[hits, 2] == WHEEL_GREY)
    counts = np.bincount(hits[grey] % pixels.shape[1], minlength=pixels.shape[1])
    # a wheel disc's columns hold up to 2 * radius pixels; both discs lose the same sparse rims
    # to this cut, so the midpoint below is unchanged
    solid = np.nonzero(counts >= _MIN_COLUMN_PIXELS)[0]
    if solid.size < _MIN_WHEEL_COLUMNS:
        return None
    # the two wheels sit symmetrically about the car's base point, so the midpoint of their
    # extent is the base column
    return (float(solid.min()) + float(solid.max())) / 2.0


def snap_to_patch(column: float, patch_px: int) -> float:
    """Centre of the ``patch_px``-wide patch that holds ``column`` (image px)."""
    if patch_px <= 1:
        return column
    return (np.floor(column / patch_px) + 0.5) * patch_px


class WheelReader:
    """MountainCar-v0's reader (a ``NumberReader``): position, zone and box from the wheels' column;
    its model name, refusal and formats are the ones answers were cached under before tasks.
    """

    name = "mountain-car"
    model_base = MODEL_BASE
    milestones: Milestones = ZONE_MILESTONES
    refusal = REFUSAL
    mcq_formats = MCQ_FORMATS

    def estimate(self, pixels: np.ndarray, patch_px: int) -> float | None:
        """The noise-free, patch-limited position read from the pixels (x units)."""
        column = wheel_column(pixels)
        if column is None:
            return None
        x = geometry.x_from_column(snap_to_patch(column, patch_px))
        return float(np.clip(x, geometry.MIN_POSITION, geometry.MAX_POSITION))

    def label_at(self, estimate: float, knobs: SimKnobs) -> str:
        """The zone of a reading before flicker, BOTTOM within ``knobs.mcq_bottom_halfwidth`` of the valley."""
        width = knobs.mcq_bottom_halfwidth
        if width is not None and abs(estimate - geometry.VALLEY_X) <= width:
            return str(geometry.Zone.BOTTOM)
        return str(geometry.zone_of(estimate))

    def box_at(self, estimate: float) -> tuple[float, float, float, float]:
        """The car's box at position ``estimate``."""
        return geometry.car_box_px(estimate)

    def read(self, pixels: np.ndarray) -> str | None:
        """The zone the frame shows, read at full resolution (None: no car in the picture)."""
        x = self.estimate(pixels, 1)
        return None if x is None else str(geometry.zone_of(x))
