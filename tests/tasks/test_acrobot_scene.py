from __future__ import annotations

import hashlib
import math
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from tests.mountain_car_helpers import sim_vlm
from vlmrl_cli.shaping.features import darkness_counts, feature_dim
from vlmrl_cli.tasks.acrobot_scene import (
    DEFAULT_POTENTIALS,
    FRAME_SHAPE,
    HEIGHT_EDGES,
    LABELS,
    MILESTONES,
    PIVOT_PIXEL,
    SCALE,
    AcrobotCamera,
    AcrobotReader,
    AcrobotRenderer,
    height_from_tip_pixel,
    label_of_height,
    label_of_state,
    tip_height,
    tip_pixel,
)
from vlmrl_cli.vlm.config import SimKnobs
from vlmrl_cli.vlm.sim import MilestoneReader

# Reader accuracy, measured with gymnasium 1.x's renderer (max |height read - true height|, link
# lengths; 1 link length = 113.6 px): 0.0114 on the 24 x 24 grid below, 0.0129 on 1500 uniform random
# states, 0.0170 on 1500 states within 17 degrees of folded (theta2 ~ pi); the 2-D tip position
# error is at most 0.021 link lengths (2.4 px). The tests allow 0.03.
TOLERANCE = 0.03
GRID = np.linspace(-math.pi, math.pi, 24, endpoint=False)  # 15 degrees apart, the full circle


@pytest.fixture(scope="module")
def renderer():
    with AcrobotRenderer() as r:
        yield r


def _true_tip_pixel(theta1: float, theta2: float) -> tuple[float, float]:
    row = PIVOT_PIXEL[0] - SCALE * tip_height(theta1, theta2)
    col = PIVOT_PIXEL[1] + SCALE * (math.sin(theta1) + math.sin(theta1 + theta2))
    return row, col


@pytest.fixture(scope="module")
def grid_reads(renderer: AcrobotRenderer) -> list[tuple[float, float, tuple[float, float] | None, str | None]]:
    reader = AcrobotReader()
    out = []
    for t1 in GRID:
        for t2 in GRID:
            pixels = renderer.render(float(t1), float(t2)).pixels
            out.append((float(t1), float(t2), tip_pixel(pixels), reader.read(pixels)))
    return out


# --- ground truth -----------------------------------------------------------------------------


def test_constants_agree() -> None:
    assert MILESTONES.labels == LABELS
    assert tuple(label for label, _ in DEFAULT_POTENTIALS) == LABELS
    potentials = [p for _, p in DEFAULT_POTENTIALS]
    assert potentials == sorted(potentials) and len(set(potentials)) == len(potentials)
    assert len(HEIGHT_EDGES) == len(LABELS) - 1 and list(HEIGHT_EDGES) == sorted(HEIGHT_EDGES)
    assert "acrobot" in MILESTONES.prompt.text and ", ".join(LABELS) in MILESTONES.prompt.text


def test_tip_height_of_known_angles() -> None:
    assert tip_height(0.0, 0.0) == -2.0  # hanging straight down
    assert tip_height(math.pi, 0.0) == 2.0  # straight up
    assert tip_height(-math.pi, 0.0) == 2.0
    assert tip_height(math.pi / 2, 0.0) == pytest.approx(0.0, abs=1e-12)  # both links horizontal
    assert tip_height(math.pi / 2, math.pi / 2) == pytest.approx(1.0)  # link 1 horizontal, link 2 up
    assert tip_height(0.0, math.pi) == pytest.approx(0.0, abs=1e-12)  # folded back: tip at the pivot
    assert label_of_height(tip_height(0.0, 0.0)) == "HANGING"
    assert label_of_height(tip_height(math.pi / 2, 0.3)) == "HIGH_SWING"
    assert label_of_height(tip_height(math.pi / 2, -0.3)) == "LOW_SWING"
    assert label_of_height(tip_height(math.pi, 0.0)) == "ABOVE_BAR"


@pytest.mark.parametrize("index", range(len(HEIGHT_EDGES)))
def test_an_edge_belongs_to_the_label_below_it(index: int) -> None:
    edge = HEIGHT_EDGES[index]
    assert label_of_height(edge) == LABELS[index]
    assert label_of_height(math.nextafter(edge, -math.inf)) == LABELS[index]
    assert label_of_height(math.nextafter(edge, math.inf)) == LABELS[index + 1]


def test_label_of_height_covers_the_range() -> None:
    assert [label_of_height(h) for h in (-2.0, -0.5, 0.5, 2.0)] == list(LABELS)
    with pytest.raises(ValueError):
        label_of_height(float("nan"))


def test_label_of_state_is_gymnasiums_terminal_test() -> None:
    env: Any = gym.make("Acrobot-v1").unwrapped
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    states = [np.concatenate([rng.uniform(-math.pi, math.pi, 2), rng.normal(size=2)]) for _ in range(2000)]
    # states whose tip is within a few ulps of the bar: t1 + t2 = arccos(-1 - cos t1) puts it on it
    for t1 in rng.uniform(math.pi / 2, math.pi, 200):
        t2 = math.acos(-1.0 - math.cos(t1)) - t1
        for k in range(-3, 4):
            states.append(np.array([t1, t2 + k * 1e-16, 0.0, 0.0]))
    states += [np.array([math.pi / 2, math.pi / 2, 0.0, 0.0]), np.array([math.pi, 0.0, 0.0, 0.0])]
    states += [s.astype(np.float32) for s in states[:300]]  # reset() leaves a float32 state
    near_bar = 0
    for state in states:
        env.state = state
        assert (label_of_state(state) == "ABOVE_BAR") == env._terminal(), state
        h = -np.cos(state[0]) - np.cos(state[1] + state[0])
        near_bar += abs(float(h) - 1.0) < 1e-12
    assert near_bar > 100  # the edge itself was exercised


# --- the pixel reader ---------------------------------------------------------------------------


def test_reader_height_within_tolerance_on_the_grid(grid_reads) -> None:
    """Max height error on this 24 x 24 grid, measured: 0.0114 link lengths (tolerance 0.03)."""
    errors = []
    for t1, t2, tip, _ in grid_reads:
        assert tip is not None, (t1, t2)
        errors.append(abs(height_from_tip_pixel(*tip) - tip_height(t1, t2)))
        true_row, true_col = _true_tip_pixel(t1, t2)
        assert math.hypot(tip[0] - true_row, tip[1] - true_col) <= TOLERANCE * SCALE, (t1, t2, tip)
    assert max(errors) <= TOLERANCE


def test_reader_label_is_the_true_label_away_from_the_edges(grid_reads) -> None:
    compared = set()
    for t1, t2, _, label in grid_reads:
        h = tip_height(t1, t2)
        if min(abs(h - edge) for edge in HEIGHT_EDGES) > TOLERANCE:
            assert label == label_of_height(h), (t1, t2, h, label)
            compared.add(label)
    assert compared == set(LABELS)


@pytest.mark.parametrize("theta1", [0.0, 0.4, math.pi / 2, -math.pi / 2, 2.5, -3.0])
def test_folded_link_two_is_found_near_the_pivot(renderer: AcrobotRenderer, theta1: float) -> None:
    """Link 2 over link 1: its tip is near the pivot, not at the far end of link 1."""
    for degrees in (-20.0, -10.0, -4.0, -1.5, -0.5, 0.0, 0.5, 1.5, 4.0, 10.0, 20.0):
        theta2 = math.pi + math.radians(degrees)
        tip = tip_pixel(renderer.render(theta1, theta2).pixels)
        assert tip is not None
        true_row, true_col = _true_tip_pixel(theta1, theta2)
        assert math.hypot(tip[0] - true_row, tip[1] - true_col) <= TOLERANCE * SCALE, (theta1, degrees, tip)


def test_no_pendulum_reads_none(renderer: AcrobotRenderer) -> None:
    reader = AcrobotReader()
    white = np.full(FRAME_SHAPE, 255, dtype=np.uint8)
    assert tip_pixel(white) is None and reader.read(white) is None
    pixels = renderer.render(1.0, -0.7).pixels.copy()
    assert tip_pixel(pixels) is not None
    pixels[(pixels != 0).any(axis=2)] = 255  # paint everything but the black bar white
    assert (pixels == 0).all(axis=2).sum() > 300  # the bar is still there
    assert tip_pixel(pixels) is None and reader.read(pixels) is None


def test_no_elbow_or_no_second_link_reads_none(renderer: AcrobotRenderer) -> None:
    frame = renderer.render(0.3, 1.2).pixels
    joints = (frame == (204, 204, 0)).all(axis=2)
    no_joints = frame.copy()
    no_joints[joints] = 255
    assert tip_pixel(no_joints) is None
    no_links = frame.copy()
    no_links[(frame == (0, 204, 204)).all(axis=2)] = 255
    assert tip_pixel(no_links) is None


def test_reader_plugs_into_the_simulated_vlm(renderer: AcrobotRenderer) -> None:
    reader: MilestoneReader = AcrobotReader()
    assert reader.name == "acrobot" and reader.milestones is MILESTONES
    vlm = sim_vlm(SimKnobs(flicker=0.0), reader=reader)
    answer = vlm.answer(MILESTONES.prompt, renderer.render(math.pi - 0.1, 0.0))
    assert "ABOVE_BAR" in answer and "acrobot" in vlm.model


def test_reader_rejects_a_non_rgb_array() -> None:
    with pytest.raises(ValueError, match="RGB"):
        tip_pixel(np.zeros((500, 500), dtype=np.uint8))


# --- rendering and the camera -------------------------------------------------------------------


def test_rendering_is_deterministic(renderer: AcrobotRenderer) -> None:
    a = renderer.render(0.8, -2.1)
    renderer.render(-1.0, 0.5)
    b = renderer.render(0.8, -2.1)
    assert a.pixels.shape == FRAME_SHAPE
    assert a.sha256 == b.sha256 == hashlib.sha256(b.pixels.tobytes()).hexdigest()
    with AcrobotRenderer() as other:
        assert other.render(0.8, -2.1).sha256 == a.sha256
    assert renderer.render(0.8, -2.0).sha256 != a.sha256
    with pytest.raises(ValueError, match="finite"):
        renderer.render(float("nan"), 0.0)


@pytest.fixture
def camera():
    cam = AcrobotCamera(bins_per_joint=12, pixel_cache=2)
    yield cam
    cam.close()


def test_one_render_per_cell(camera: AcrobotCamera) -> None:
    # 12 bins: 30 degrees wide; bin centres at -165, -135, ..., 165 degrees
    a = camera.view(math.radians(16), math.radians(-44))
    b = camera.view(math.radians(29), math.radians(-31))  # the same cell (15, -45)
    c = camera.view(math.radians(31), math.radians(-44))  # the next bin of theta1
    assert a.key == b.key != c.key
    assert camera.renders == 2 and camera.cells == 2
    assert camera.cell_angles(math.radians(16), math.radians(-44)) == pytest.approx(
        (math.radians(15), math.radians(-45)))


def test_angles_a_turn_apart_share_a_cell(camera: AcrobotCamera) -> None:
    for t1, t2 in ((0.4, -1.3), (3.0, -3.0), (-2.2, 2.9)):
        cell = camera.cell_angles(t1, t2)
        assert camera.cell_angles(t1 + 2 * math.pi, t2 - 4 * math.pi) == cell
        assert all(-math.pi <= angle < math.pi for angle in cell)
        assert camera.view(t1, t2).key == camera.view(t1 - 2 * math.pi, t2 + 2 * math.pi).key
    assert camera.renders == 3
    assert camera.cell_angles(math.pi, 0.0) == camera.cell_angles(-math.pi, 0.0)


def test_grid_states_bound_the_frames() -> None:
    assert len(AcrobotCamera().grid_states()) == 48**2
    cam = AcrobotCamera(bins_per_joint=6)
    states = cam.grid_states()
    assert len(states) == 36 == len(set(states))
    assert all(cam.cell_angles(*s) == s for s in states)  # each is the centre of its own cell
    rng = np.random.default_rng(0)
    assert {cam.cell_angles(*rng.uniform(-10.0, 10.0, 2)) for _ in range(500)} <= set(states)


def test_features_are_the_frames_darkness(camera: AcrobotCamera) -> None:
    view = camera.view(1.0, 1.0)
    assert view.features.shape == (feature_dim(FRAME_SHAPE),)
    np.testing.assert_array_equal(view.features, darkness_counts(view.frame().pixels))
    with pytest.raises(ValueError):
        view.features[0] = 0


def test_pixels_are_an_lru_and_rerendered_on_demand(camera: AcrobotCamera) -> None:
    first = camera.view(0.0, 0.0)
    pixels = first.frame().pixels.copy()
    camera.view(1.0, 0.0)
    camera.view(2.0, 0.0)  # pixel_cache=2 drops the first frame
    assert camera.renders == 3
    again = first.frame()
    assert camera.renders == 4
    assert again.sha256 == first.key == hashlib.sha256(again.pixels.tobytes()).hexdigest()
    np.testing.assert_array_equal(again.pixels, pixels)
    camera.view(0.0, 0.0)  # memoised: no render
    assert camera.renders == 4


def test_look_reads_the_sims_state(camera: AcrobotCamera, renderer: AcrobotRenderer) -> None:
    sim: Any = gym.make("Acrobot-v1").unwrapped
    sim.reset(seed=0)
    sim.state = np.array([1.0, -0.5, 0.3, -0.2])
    view = camera.look(sim)
    assert view.key == renderer.render(*camera.cell_angles(1.0, -0.5)).sha256
    sim.state = np.array([0.9, -0.45, 2.0, 1.0])  # same cell (45, -15 degrees), other velocities
    assert camera.look(sim) is view
    sim.state = np.array([-2.0, 2.0, 0.0, 0.0])
    assert camera.look(sim).key != view.key
    assert camera.renders == 2
    sim.state = None
    with pytest.raises(ValueError, match="reset"):
        camera.look(sim)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"bins_per_joint": 0}, "bins_per_joint"), ({"pixel_cache": 0}, "pixel_cache"),
])
def test_invalid_camera_settings_are_rejected(kwargs: dict[str, int], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        AcrobotCamera(**kwargs)


def test_non_finite_angle_is_rejected(camera: AcrobotCamera) -> None:
    with pytest.raises(ValueError, match="finite"):
        camera.view(0.0, float("inf"))
