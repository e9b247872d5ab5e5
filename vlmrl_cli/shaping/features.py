"""Exact integer block-darkness features of a frame, from its pixels only: the same on every CPU
(docs/method.md)."""

from __future__ import annotations

import numpy as np

BLOCK = 20  # pixels per block side; 400 x 600 frames -> a 20 x 30 grid
FRAME_SHAPE = (400, 600, 3)
FEATURE_DIM = (FRAME_SHAPE[0] // BLOCK) * (FRAME_SHAPE[1] // BLOCK)
LUMA_WEIGHTS = (299, 587, 114)  # ITU-R BT.601 luma weights x 1000: grey level of an RGB pixel
FEATURE_UNIT = 255 * sum(LUMA_WEIGHTS) * BLOCK * BLOCK  # the darkness count of an all-black block


def darkness_counts(pixels: np.ndarray) -> np.ndarray:
    """Block darkness of an RGB frame: ``(400, 600, 3)`` uint8 -> ``(600,)`` int64, row-major blocks,
    each ``sum(255 * 1000 - (299 r + 587 g + 114 b))`` over the block, in ``[0, FEATURE_UNIT]``."""
    if pixels.ndim != 3 or pixels.shape[2] != 3 or pixels.shape[0] % BLOCK or pixels.shape[1] % BLOCK:
        raise ValueError(f"expected an RGB frame whose sides are multiples of {BLOCK} px (MountainCar: "
                         f"{FRAME_SHAPE}), got {pixels.shape}")
    h, w = pixels.shape[0] // BLOCK, pixels.shape[1] // BLOCK
    # Sum each channel over a block first (exact integers, so the order changes nothing), then
    # weight: sum(C - (wr r + wg g + wb b)) = BLOCK^2 C - (wr sum r + wg sum g + wb sum b).
    # Rows first (a contiguous reduction), then columns: a third faster than weighting every pixel.
    rows = np.ascontiguousarray(pixels).reshape(h, BLOCK, pixels.shape[1] * 3).sum(axis=1, dtype=np.int32)
    sums = rows.reshape(h, w, BLOCK, 3).sum(axis=2, dtype=np.int64)
    wr, wg, wb = LUMA_WEIGHTS
    weighted = sums[..., 0] * wr + sums[..., 1] * wg + sums[..., 2] * wb
    return (255 * sum(LUMA_WEIGHTS) * BLOCK * BLOCK - weighted).reshape(-1)


def feature_dim(frame_shape: tuple[int, ...]) -> int:
    """How many blocks ``darkness_counts`` gives a frame of ``frame_shape`` (H, W, 3)."""
    return (frame_shape[0] // BLOCK) * (frame_shape[1] // BLOCK)
