from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from vlmrl_cli.shaping.features import BLOCK, FEATURE_DIM, FEATURE_UNIT, darkness_counts, feature_dim
from vlmrl_cli.tasks.mountain_car.geometry import SCALE
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer


@pytest.fixture(scope="module")
def renderer():
    with FrameRenderer() as r:
        yield r


@settings(max_examples=25, deadline=None)
@given(arrays(np.uint8, (400, 600, 3), elements=st.integers(0, 255), fill=st.integers(0, 255)))
def test_features_are_block_means_of_darkness(pixels: np.ndarray) -> None:
    f = darkness_counts(pixels) / FEATURE_UNIT
    assert f.shape == (FEATURE_DIM,) and f.dtype == np.float64
    assert np.all((f >= 0) & (f <= 1))
    grey = pixels.astype(np.float64) @ np.array([0.299, 0.587, 0.114])
    block = (255.0 - grey[:BLOCK, :BLOCK]) / 255.0
    assert f[0] == pytest.approx(block.mean(), abs=1e-12)


@settings(max_examples=10, deadline=None)
@given(arrays(np.uint8, (400, 600, 3), elements=st.integers(0, 255), fill=st.integers(0, 255)), st.data())
def test_counts_equal_a_scalar_integer_sum(pixels: np.ndarray, data: st.DataObject) -> None:
    """The vectorised counts are the exact integer sums a plain Python loop gives."""
    counts = darkness_counts(pixels)
    b = data.draw(st.integers(0, FEATURE_DIM - 1))
    r0, c0 = (b // (600 // BLOCK)) * BLOCK, (b % (600 // BLOCK)) * BLOCK
    block = pixels[r0 : r0 + BLOCK, c0 : c0 + BLOCK].reshape(-1, 3).tolist()
    assert int(counts[b]) == sum(255_000 - (299 * r + 587 * g + 114 * bl) for r, g, bl in block)


def test_rejects_a_frame_of_the_wrong_shape() -> None:
    with pytest.raises(ValueError, match="multiples of 20 px"):
        darkness_counts(np.zeros((10, 10, 3), dtype=np.uint8))


@pytest.mark.parametrize("x", [-1.0, -0.52, -0.2, 0.3])
def test_distance_grows_smoothly_with_small_displacements(renderer: FrameRenderer, x: float) -> None:
    """Block averaging: d(1 px) < d(5 px) < d(20 px), about 0.075 per pixel, and no jump at 1 px."""
    f0 = darkness_counts(renderer.render(x).pixels) / FEATURE_UNIT
    d = {px: float(np.linalg.norm(darkness_counts(renderer.render(x + px / SCALE).pixels) / FEATURE_UNIT - f0))
         for px in (1, 5, 20)}
    assert 0 < d[1] < d[5] < d[20]
    assert d[1] < 0.15
    assert 0.2 < d[5] < 0.6


def test_far_apart_frames_are_at_the_saturated_distance(renderer: FrameRenderer) -> None:
    a, b = (darkness_counts(renderer.render(x).pixels) / FEATURE_UNIT for x in (-1.0, -0.2))
    assert 1.2 < float(np.linalg.norm(a - b)) < 1.7


@settings(max_examples=10, deadline=None)
@given(arrays(np.uint8, (400, 600, 3), elements=st.integers(0, 255), fill=st.integers(0, 255)))
def test_counts_equal_the_per_pixel_weighted_sum_everywhere(pixels: np.ndarray) -> None:
    """Summing channels per block before weighting (the fast path) changes no count."""
    px = pixels.astype(np.int64)
    darkness = 255_000 - (px[..., 0] * 299 + px[..., 1] * 587 + px[..., 2] * 114)
    reference = darkness.reshape(400 // BLOCK, BLOCK, 600 // BLOCK, BLOCK).sum(axis=(1, 3)).reshape(-1)
    assert np.array_equal(darkness_counts(pixels), reference)


def test_any_frame_of_whole_blocks_has_one_feature_per_block() -> None:
    frame = np.zeros((500, 500, 3), dtype=np.uint8)
    frame[:20, :20] = 255  # the first block white
    counts = darkness_counts(frame)
    assert counts.shape == (feature_dim(frame.shape),) == (625,)
    assert counts[0] == 0 and bool((counts[1:] == FEATURE_UNIT).all())
