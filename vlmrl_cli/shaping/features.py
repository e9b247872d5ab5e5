"""A low-dimensional visual descriptor of a frame, computed from its pixels only.

Darkness ``(255 - grey) / 255`` averaged over ``BLOCK x BLOCK`` pixel blocks: a (400, 600)
frame becomes a 20 x 30 grid, flattened to ``D = 600`` values in ``[0, 1]``. The static parts
of the picture (track, flag) are the same in every frame and cancel in a difference, so the
Euclidean distance between two frames' features measures how far the car moved. Block
averaging makes that distance grow smoothly (about linearly) with small moves instead of
jumping pixel by pixel; once the two car positions no longer share a block the distance
saturates at the car's own "mass" in feature space.

The features are computed in integers, exactly: grey is ``299 r + 587 g + 114 b`` (ITU-R
BT.601 luma x 1000) and a block's darkness is the integer sum ``darkness_counts`` over its
400 pixels, in units of ``1 / FEATURE_UNIT``. A float pipeline (float32 luma through a BLAS
matrix-vector product) rounded differently on AVX-512 and AVX2 CPUs and made the VLM arms
train different agents on different machines; integers round nowhere.

Measured with gymnasium's renderer at 40 positions x in [-1.15, 0.25], the car shifted right
by ``dx`` pixels (1 px = 1.8 / 600 = 0.003 x units); L2 distance, median [min, max]:

=========  ================================================
shift      feature distance
=========  ================================================
1 px       0.077 [0.039, 0.110]
5 px       0.37  [0.25, 0.50]
20 px      1.14  [0.71, 1.35]
100 px     1.44  [1.33, 1.51]  (saturated from about 40 px on)
=========  ================================================

So distance is about 0.075 per pixel of displacement up to ~15 px, and ~1.4 for any two
frames whose cars do not overlap. An RBF bandwidth of 0.25-0.3 blends labels over a few
pixels while far prototypes (weight ~exp(-1.4^2 / (2 h^2)) < 1e-5) cannot swamp near ones.
"""

from __future__ import annotations

import numpy as np

BLOCK = 20  # pixels per block side; 400 x 600 frames -> a 20 x 30 grid
FRAME_SHAPE = (400, 600, 3)
FEATURE_DIM = (FRAME_SHAPE[0] // BLOCK) * (FRAME_SHAPE[1] // BLOCK)
LUMA_WEIGHTS = (299, 587, 114)  # ITU-R BT.601 luma weights x 1000: grey level of an RGB pixel
FEATURE_UNIT = 255 * sum(LUMA_WEIGHTS) * BLOCK * BLOCK  # the darkness count of an all-black block


def darkness_counts(pixels: np.ndarray) -> np.ndarray:
    """Exact block darkness of an RGB frame: ``(400, 600, 3)`` uint8 -> ``(600,)`` int64 (any
    frame whose sides are multiples of ``BLOCK``: ``(H / BLOCK) * (W / BLOCK)`` blocks, row-major).

    Entry ``b`` is ``sum over the block's pixels of (255 * 1000 - (299 r + 587 g + 114 b))``,
    in ``[0, FEATURE_UNIT]``; ``frame_features`` is this divided by ``FEATURE_UNIT``. Integer
    sums are exact, so every CPU gives the same counts.

    Example:
        >>> black = np.zeros((400, 600, 3), dtype=np.uint8)
        >>> c = darkness_counts(black)
        >>> c.dtype, bool((c == FEATURE_UNIT).all())
        (dtype('int64'), True)
    """
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


def frame_features(pixels: np.ndarray) -> np.ndarray:
    """Block-mean darkness of an RGB frame: ``(400, 600, 3)`` uint8 -> ``(600,)`` float64 in [0, 1].

    ``darkness_counts(pixels) / FEATURE_UNIT``: each value is the exact ratio rounded once.

    Example:
        >>> white = np.full((400, 600, 3), 255, dtype=np.uint8)
        >>> f = frame_features(white)
        >>> f.shape, f.dtype, float(f.max())
        ((600,), dtype('float64'), 0.0)
    """
    return darkness_counts(pixels) / FEATURE_UNIT


def feature_dim(frame_shape: tuple[int, ...]) -> int:
    """How many blocks ``darkness_counts`` gives a frame of ``frame_shape`` (H, W, 3).

    Example:
        >>> feature_dim((400, 600, 3)) == FEATURE_DIM, feature_dim((500, 500, 3))
        (True, 625)
    """
    return (frame_shape[0] // BLOCK) * (frame_shape[1] // BLOCK)
