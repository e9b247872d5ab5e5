"""Acrobot-v1's scene: labels of the tip height, ground truth, renderer, pixel reader and camera.
The constants mirror ``AcrobotEnv.render`` (500x500, pivot at the centre, y flipped). The reader
sees pixels only; the camera, the one part that reads the state, snaps both angles to a grid."""

from __future__ import annotations

import bisect
import math
from typing import Any

import numpy as np
from gymnasium.envs.classic_control.acrobot import AcrobotEnv

from vlmrl_cli.frames.render import EnvRenderer, Frame
from vlmrl_cli.shaping.camera import CellCamera, FrameView
from vlmrl_cli.vlm.prompts import Milestones, mcq_prompt

SCREEN = AcrobotEnv.SCREEN_DIM  # 500
FRAME_SHAPE = (SCREEN, SCREEN, 3)  # Acrobot's rgb_array frame
#: pixels per link length: gymnasium maps [-2.2, 2.2] link lengths onto the screen
SCALE = SCREEN / (2 * (AcrobotEnv.LINK_LENGTH_1 + AcrobotEnv.LINK_LENGTH_2 + 0.2))
#: image (row, col) of the pivot: gymnasium draws it at surface (250, 250) and flips the rows
PIVOT_PIXEL = (SCREEN - 1 - SCREEN / 2, SCREEN / 2)
LINK_COLOUR = (0, 204, 204)
JOINT_COLOUR = (204, 204, 0)
JOINT_RADIUS_PX = int(0.1 * SCALE)

LABELS: tuple[str, ...] = ("HANGING", "LOW_SWING", "HIGH_SWING", "ABOVE_BAR")  # low to high
#: Upper edges of every label but the last, in link lengths of tip height. An edge belongs to
#: the label below it (``(lower, upper]``), so that ``ABOVE_BAR`` is exactly gymnasium's
#: terminal condition ``tip_height > 1.0`` (1.0 is the bar).
HEIGHT_EDGES: tuple[float, ...] = (-1.0, 0.0, 1.0)
DEFAULT_POTENTIALS: tuple[tuple[str, float], ...] = (
    ("HANGING", 0.0), ("LOW_SWING", 0.2), ("HIGH_SWING", 0.6), ("ABOVE_BAR", 1.0),
)
MILESTONES = Milestones(LABELS, mcq_prompt(
    "This image shows a two-link pendulum (an acrobot) hanging from a pivot, with a horizontal line "
    "above it marking the goal height. How high is the free end of the lower link?", LABELS))


def tip_height(theta1: float, theta2: float) -> float:
    """Height of the tip above the pivot, in link lengths, in [-2, 2], as gymnasium computes it."""
    return float(-np.cos(theta1) - np.cos(theta2 + theta1))


def label_of_height(h: float) -> str:
    """The label whose height interval ``(lower, upper]`` holds ``h`` (see ``HEIGHT_EDGES``)."""
    if math.isnan(h):
        raise ValueError("tip height must not be NaN")
    return LABELS[bisect.bisect_left(HEIGHT_EDGES, h)]


def label_of_state(state: np.ndarray) -> str:
    """The label of a state ``[theta1, theta2, ...]``, in the state's own dtype as ``AcrobotEnv._terminal``
    computes it (``ABOVE_BAR`` is its terminal test bit for bit).
    """
    return label_of_height(float(-np.cos(state[0]) - np.cos(state[1] + state[0])))


class AcrobotRenderer(EnvRenderer):
    """Renders Acrobot-v1 at arbitrary angles, headless (about 3 ms a frame)."""

    def __init__(self) -> None:
        super().__init__("Acrobot-v1")

    def render(self, theta1: float, theta2: float, frame_id: str | None = None,
               sha256: str | None = None) -> Frame:
        """The frame of joint angles (radians) ``theta1`` (from straight down) and ``theta2`` (relative to
        link 1); ``sha256``: its digest, when known."""
        if not (math.isfinite(theta1) and math.isfinite(theta2)):
            raise ValueError(f"angles must be finite, got theta1={theta1}, theta2={theta2}")
        return self.draw(np.array([theta1, theta2, 0.0, 0.0], dtype=np.float64), frame_id, sha256)


# --- the pixel reader ------------------------------------------------------------------------
# At least this many exact joint-colour pixels half a link from the pivot make the elbow (a whole one: ~380).
_MIN_ELBOW_PIXELS = 100
# gymnasium centres a joint circle at int() of its surface coordinates (positive, so floor): the
# drawn centre is on average half a pixel below (image rows grow downwards) and left of the true one.
_ELBOW_CORRECTION = (-0.5, 0.5)
# A pixel within this much of the link colour in every channel is link (admits only strong anti-aliasing).
_LINK_TOLERANCE = 24
# Rays from the elbow, every half degree, sampled every pixel from just outside the elbow circle
# to nearly a link length: a ray counts as "arm" when every sample is link colour.
_RAY_ANGLES = 720
_RAY_START_PX = float(JOINT_RADIUS_PX + 4)
_RAY_END_PX = math.floor(SCALE) - 3.0
_ANGLES = np.arange(_RAY_ANGLES) * (2 * math.pi / _RAY_ANGLES)
_RADII = np.arange(_RAY_START_PX, _RAY_END_PX + 1.0)
_RAY_ROWS = np.sin(_ANGLES)[:, None] * _RADII[None, :]
_RAY_COLS = np.cos(_ANGLES)[:, None] * _RADII[None, :]
# Link 2's rays form a run of 22-28 (11.8 degrees); link 1 leaves runs of at most 3 beside the pivot.
_MIN_ARM_RAYS = 8


def _elbow_pixel(pixels: np.ndarray) -> tuple[float, float] | None:
    """Centre (row, col) of the elbow's joint circle, or None when it is not in the picture."""
    rows, cols = np.nonzero(pixels[:, :, 2] == JOINT_COLOUR[2])  # one channel first: few pixels pass
    joint = (pixels[rows, cols, 0] == JOINT_COLOUR[0]) & (pixels[rows, cols, 1] == JOINT_COLOUR[1])
    rows, cols = rows[joint], cols[joint]
    # the pivot's circle is within one radius of the pivot, the elbow's a link length away
    far = np.hypot(rows - PIVOT_PIXEL[0], cols - PIVOT_PIXEL[1]) > SCALE / 2
    if np.count_nonzero(far) < _MIN_ELBOW_PIXELS:
        return None
    return float(rows[far].mean()) + _ELBOW_CORRECTION[0], float(cols[far].mean()) + _ELBOW_CORRECTION[1]


def _arm_runs(arm: np.ndarray) -> list[tuple[int, int]]:
    """(first index, length) of each circular run of True in ``arm``."""
    if not arm.any() or arm.all():
        return []
    start = int(np.argmin(arm))  # a False entry: no run wraps past it
    step = np.diff(np.concatenate(([0], np.roll(arm, -start).astype(np.int8), [0])))
    firsts, ends = np.nonzero(step == 1)[0], np.nonzero(step == -1)[0]
    return [((int(a) + start) % arm.size, int(b - a)) for a, b in zip(firsts, ends, strict=True)]


def tip_pixel(pixels: np.ndarray) -> tuple[float, float] | None:
    """Image (row, col) of the tip, from an RGB frame's pixels only, or None when no pendulum shows:
    one link length from the elbow (the joint circle a link from the pivot) along the bundle of
    rays that stay in link colour for almost a link (link 1's run into the pivot's circle first).
    """
    if pixels.ndim != 3 or pixels.shape[2] != 3:
        raise ValueError(f"expected an RGB frame (H, W, 3), got {pixels.shape}")
    elbow = _elbow_pixel(pixels)
    if elbow is None:
        return None
    height, width = pixels.shape[:2]
    rows = np.rint(elbow[0] + _RAY_ROWS).astype(np.intp)
    cols = np.rint(elbow[1] + _RAY_COLS).astype(np.intp)
    inside = ((rows >= 0) & (rows < height) & (cols >= 0) & (cols < width)).all(axis=1)
    flat = np.ascontiguousarray(pixels).reshape(-1, 3)
    where = rows.clip(0, height - 1) * width + cols.clip(0, width - 1)
    link = np.ones(where.shape, dtype=bool)
    for channel, value in enumerate(LINK_COLOUR):  # one channel at a time: a third of the time of all three
        sample = flat[where, channel]
        link &= (sample >= max(value - _LINK_TOLERANCE, 0)) & (sample <= min(value + _LINK_TOLERANCE, 255))
    arm = link.all(axis=1) & inside
    runs = [run for run in _arm_runs(arm) if run[1] >= _MIN_ARM_RAYS]
    if not runs:
        return None
    first, length = max(runs, key=lambda run: run[1])
    angle = (first + (length - 1) / 2) * (2 * math.pi / _RAY_ANGLES)
    return elbow[0] + SCALE * math.sin(angle), elbow[1] + SCALE * math.cos(angle)


def height_from_tip_pixel(row: float, col: float) -> float:
    """Tip height (link lengths) of an image position (row, col); only the row matters."""
    return (PIVOT_PIXEL[0] - row) / SCALE


class AcrobotReader:
    """The simulated VLM's reader for Acrobot: the label of the height of ``tip_pixel``."""

    name: str = "acrobot"
    milestones: Milestones = MILESTONES

    def read(self, pixels: np.ndarray) -> str | None:
        tip = tip_pixel(pixels)
        if tip is None:
            return None
        return label_of_height(height_from_tip_pixel(*tip))


class AcrobotCamera(CellCamera[tuple[int, int]]):
    """Renders Acrobot with both angles wrapped into [-pi, pi) and shown at the centre of one of
    ``bins_per_joint`` bins (at most ``bins_per_joint ** 2`` frames); memoises per cell.
    """

    def __init__(self, bins_per_joint: int = 48, pixel_cache: int = 256) -> None:
        if bins_per_joint < 1:
            raise ValueError(f"bins_per_joint must be >= 1, got {bins_per_joint}")
        super().__init__(pixel_cache)
        self.bins_per_joint = int(bins_per_joint)
        self._width = 2 * math.pi / self.bins_per_joint
        self._renderer: AcrobotRenderer | None = None

    def _bin(self, theta: float) -> int:
        if not math.isfinite(theta):
            raise ValueError(f"angles must be finite, got {theta}")
        wrapped = (theta + math.pi) % (2 * math.pi)  # [0, 2 pi), or 2 pi itself by rounding
        return min(int(wrapped // self._width), self.bins_per_joint - 1)

    def _centre(self, index: int) -> float:
        return -math.pi + (index + 0.5) * self._width

    def _cell(self, theta1: float, theta2: float) -> tuple[int, int]:
        return self._bin(float(theta1)), self._bin(float(theta2))

    def cell_angles(self, theta1: float, theta2: float) -> tuple[float, float]:
        """The angles (radians, in [-pi, pi)) whose frame ``look`` shows for ``theta1``, ``theta2``."""
        i, j = self._cell(theta1, theta2)
        return self._centre(i), self._centre(j)

    def grid_states(self) -> list[tuple[float, float]]:
        """Every (theta1, theta2) the camera can show: ``bins_per_joint ** 2`` of them."""
        centres = [self._centre(i) for i in range(self.bins_per_joint)]
        return [(a, b) for a in centres for b in centres]

    def _draw(self, cell: tuple[int, int], sha256: str | None) -> Frame:
        if self._renderer is None:
            self._renderer = AcrobotRenderer()
        return self._renderer.render(self._centre(cell[0]), self._centre(cell[1]), sha256=sha256)

    def view(self, theta1: float, theta2: float) -> FrameView:
        """The view of the pendulum at angles ``theta1``, ``theta2``, rendered at most once per cell."""
        return self._view_of(self._cell(theta1, theta2))

    def look(self, sim: Any) -> FrameView:
        """The view of the simulator ``sim`` (the unwrapped AcrobotEnv): its angles ``state[:2]``."""
        state = sim.state
        if state is None:
            raise ValueError("the simulator has no state yet: reset it first")
        return self.view(float(state[0]), float(state[1]))
