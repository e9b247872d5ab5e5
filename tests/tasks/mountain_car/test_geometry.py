"""Ground truth vs gymnasium's pixels: the computed box must hug the drawn car."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vlmrl_cli.tasks.mountain_car import geometry
from vlmrl_cli.tasks.mountain_car.geometry import GroundTruth, Zone, car_box_px, zone_of
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer


@pytest.fixture(scope="module")
def renderer():
    with FrameRenderer() as r:
        yield r


def _drawn_car_bbox(renderer: FrameRenderer, x: float) -> tuple[int, int, int, int]:
    """Bounding box of the pixels that belong to the car at x: non-white pixels that differ from
    a frame with the car far away, minus the far car's own box."""
    far = -1.0 if x > -0.2 else 0.4
    a, b = renderer.render(x).pixels, renderer.render(far).pixels
    mask = np.any(a != b, axis=-1) & np.any(a != 255, axis=-1)
    fx0, fy0, fx1, fy1 = car_box_px(far)
    mask[int(fy0) - 2 : int(fy1) + 3, int(fx0) - 2 : int(fx1) + 3] = False
    rows, cols = np.nonzero(mask)
    return int(cols.min()), int(rows.min()), int(cols.max()), int(rows.max())


@pytest.mark.parametrize("x", [*np.round(np.linspace(-1.15, 0.55, 18), 3).tolist(), -0.5, -0.69])
def test_car_box_matches_rendered_pixels(renderer: FrameRenderer, x: float) -> None:
    drawn = _drawn_car_bbox(renderer, x)
    computed = car_box_px(x)
    assert np.allclose(drawn, computed, atol=2.0), (x, drawn, computed)


def test_zone_of_is_monotone_over_the_track() -> None:
    xs = np.linspace(geometry.MIN_POSITION, geometry.MAX_POSITION, 2001)
    indices = [geometry.ZONES.index(zone_of(float(x))) for x in xs]
    assert indices == sorted(indices)
    assert {geometry.ZONES[i] for i in indices} == set(Zone)


@given(st.floats(geometry.MIN_POSITION, geometry.MAX_POSITION), st.floats(geometry.MIN_POSITION, geometry.MAX_POSITION))
def test_zone_order_follows_x(a: float, b: float) -> None:
    lo, hi = sorted((a, b))
    assert geometry.ZONES.index(zone_of(lo)) <= geometry.ZONES.index(zone_of(hi))


def test_paper_frames_have_the_zones_the_table_assumes() -> None:
    assert GroundTruth.of(-0.50).zone is Zone.BOTTOM
    assert GroundTruth.of(-0.69).zone is Zone.LEFT_SLOPE


@given(st.floats(0, geometry.SCREEN_WIDTH))
def test_x_from_column_inverts_the_scale(column: float) -> None:
    x = geometry.x_from_column(column)
    assert (x - geometry.MIN_POSITION) * geometry.SCALE == pytest.approx(column, abs=1e-9)


def test_render_is_deterministic(renderer: FrameRenderer) -> None:
    assert renderer.render(-0.5).sha256 == renderer.render(-0.5).sha256 != renderer.render(-0.51).sha256
