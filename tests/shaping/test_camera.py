from __future__ import annotations

import hashlib

import numpy as np
import pytest

from vlmrl_cli.shaping.camera import FrameView
from vlmrl_cli.shaping.features import darkness_counts
from vlmrl_cli.tasks.mountain_car.camera import Camera
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer


@pytest.fixture
def camera():
    cam = Camera(render_quantum=0.001, pixel_cache=2)
    yield cam
    cam.close()


def test_one_render_per_grid_cell(camera: Camera) -> None:
    a = camera.view(-0.5)
    b = camera.view(-0.5004)  # same cell (snaps to -0.500)
    c = camera.view(-0.4)
    assert a.key == b.key != c.key
    assert camera.renders == 2 and camera.cells == 2


def test_view_matches_gymnasiums_frame_at_the_snapped_position(camera: Camera) -> None:
    view = camera.view(-0.52349)
    with FrameRenderer() as r:
        frame = r.render(-0.523)
    assert view.key == frame.sha256
    np.testing.assert_array_equal(view.features, darkness_counts(frame.pixels))
    assert view.frame().sha256 == view.key


def test_pixels_are_an_lru_and_rerendered_on_demand(camera: Camera) -> None:
    views = [camera.view(x) for x in (-0.9, -0.6, -0.3)]  # pixel_cache=2 drops the first
    assert camera.renders == 3
    again = views[0].frame()
    assert camera.renders == 4
    # drawn again with its known key, not hashed again: the pixels still hash to that key
    assert again.sha256 == views[0].key == hashlib.sha256(again.pixels.tobytes()).hexdigest()
    views[2].frame()  # still cached
    assert camera.renders == 4
    camera.view(-0.9)  # memoised key and features: no render
    assert camera.renders == 4


def test_positions_are_clipped_to_the_track(camera: Camera) -> None:
    assert camera.view(-5.0).key == camera.view(-1.2).key
    assert camera.view(0.6000004).key == camera.view(0.6).key


def test_features_are_read_only(camera: Camera) -> None:
    with pytest.raises(ValueError):
        camera.view(-0.5).features[0] = 1.0


def test_view_of_a_frame_needs_no_camera() -> None:
    with FrameRenderer() as r:
        frame = r.render(-0.5)
    view = FrameView.of_frame(frame)
    assert view.key == frame.sha256 and view.frame() is frame


@pytest.mark.parametrize("q", [0.0, -0.001, float("nan"), 5.0])
def test_invalid_quantum_is_rejected(q: float) -> None:
    with pytest.raises(ValueError, match="render_quantum"):
        Camera(render_quantum=q)


def test_non_finite_position_is_rejected(camera: Camera) -> None:
    with pytest.raises(ValueError, match="finite"):
        camera.view(float("nan"))
