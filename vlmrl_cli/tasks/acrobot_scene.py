"""The pure scene pieces of the Acrobot-v1 task: labels, ground truth, renderer, pixel reader, camera.

Everything here mirrors ``gymnasium.envs.classic_control.acrobot.AcrobotEnv.render``: a 500x500
RGB frame, white background, both links drawn as (0, 204, 204) rectangles one link length long
(``SCALE`` = 500 / 4.4 px) and 0.2 link lengths wide, a (204, 204, 0) joint circle of radius
``int(0.1 * SCALE)`` = 11 px at the pivot (drawn after link 1) and at the elbow (drawn last, so
always whole), a black one-pixel bar at tip height 1.0 (drawn first, under the links), and the
drawing flipped vertically. The pivot is at the screen centre, image (row, col) ``PIVOT_PIXEL``;
a state ``[theta1, theta2, ...]`` puts the elbow at ``(sin t1, -cos t1)`` and the tip at
``(sin t1 + sin(t1 + t2), -cos t1 - cos(t1 + t2))`` (x right, height up, link lengths).

The milestone of a frame is the height of the free end of link 2, ``tip_height`` in
``[-2, 2]``: ``HANGING`` up to -1, ``LOW_SWING`` up to 0, ``HIGH_SWING`` up to 1 (the bar:
gymnasium terminates the episode once the tip is strictly above it) and ``ABOVE_BAR`` beyond.

``AcrobotReader`` (the simulated VLM's reader) finds the tip from the pixels only; the ground
truth functions (``label_of_state``) are the answer key, never its input. ``AcrobotCamera`` is
the one component that reads the simulator's state: it snaps both angles to a grid, so a run
shows at most ``bins_per_joint ** 2`` distinct frames.
"""

from __future__ import annotations

import bisect
import math
from typing import Any

import numpy as np
from gymnasium.envs.classic_control.acrobot import AcrobotEnv

from vlmrl_cli.frames.render import Frame
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
    """Height of the free end of link 2 above the pivot, in link lengths: ``-cos t1 - cos(t1 + t2)``.

    In ``[-2, 2]``; gymnasium's episode ends when it exceeds 1.0. Computed as gymnasium computes
    it (numpy's cosine, same order), so that the comparison with the bar agrees to the last bit.

    Example:
        >>> tip_height(0.0, 0.0), tip_height(math.pi, 0.0), round(tip_height(math.pi / 2, 0.0), 12)
        (-2.0, 2.0, -0.0)
    """
    return float(-np.cos(theta1) - np.cos(theta2 + theta1))


def label_of_height(h: float) -> str:
    """The label whose height interval ``(lower, upper]`` holds ``h`` (see ``HEIGHT_EDGES``).

    Example:
        >>> label_of_height(-2.0), label_of_height(-1.0), label_of_height(0.5), label_of_height(1.0)
        ('HANGING', 'HANGING', 'HIGH_SWING', 'HIGH_SWING')
        >>> label_of_height(1.0000001)
        'ABOVE_BAR'
    """
    if math.isnan(h):
        raise ValueError("tip height must not be NaN")
    return LABELS[bisect.bisect_left(HEIGHT_EDGES, h)]


def label_of_state(state: np.ndarray) -> str:
    """Ground truth: the label of a simulator state ``[theta1, theta2, dtheta1, dtheta2]``.

    The height is computed in the state's own dtype, exactly as ``AcrobotEnv._terminal`` does
    (``reset`` leaves a float32 state), so ``ABOVE_BAR`` is gymnasium's terminal test bit for bit.

    Example:
        >>> label_of_state(np.array([0.0, 0.0, 0.0, 0.0])), label_of_state(np.array([3.0, 0.1, 0.0, 0.0]))
        ('HANGING', 'ABOVE_BAR')
    """
    return label_of_height(float(-np.cos(state[0]) - np.cos(state[1] + state[0])))


class AcrobotRenderer:
    """Renders Acrobot-v1 at arbitrary angles with ``render_mode="rgb_array"``.

    Holds one unwrapped gymnasium env; no display is needed. The velocities do not change the
    picture, so only the two angles are taken. A render costs about 3 ms (the first one ~0.2 s:
    pygame starts).

    Example:
        >>> with AcrobotRenderer() as renderer:
        ...     frame = renderer.render(0.0, 0.0)
        >>> frame.pixels.shape, len(frame.sha256)
        ((500, 500, 3), 64)
    """

    def __init__(self) -> None:
        import gymnasium as gym

        self._env: Any = gym.make("Acrobot-v1", render_mode="rgb_array").unwrapped
        self._env.reset(seed=0)

    def render(self, theta1: float, theta2: float, frame_id: str | None = None,
               sha256: str | None = None) -> Frame:
        """Render the frame of joint angles ``theta1`` (link 1 from straight down) and ``theta2``
        (link 2 relative to link 1), radians.

        ``sha256``: the digest of this very frame, known from an earlier render of the same
        angles (gymnasium draws it identically), so it is not hashed again.
        """
        if not (math.isfinite(theta1) and math.isfinite(theta2)):
            raise ValueError(f"angles must be finite, got theta1={theta1}, theta2={theta2}")
        self._env.state = np.array([theta1, theta2, 0.0, 0.0], dtype=np.float64)
        return Frame.drawn(self._env.render(), frame_id, sha256)

    def close(self) -> None:
        self._env.close()

    def __enter__(self) -> AcrobotRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# --- the pixel reader ------------------------------------------------------------------------
# At least this many exact joint-colour pixels farther than half a link from the pivot make the
# elbow circle (a whole one has ~380; anti-aliasing strays are single pixels).
_MIN_ELBOW_PIXELS = 100
# gymnasium centres a joint circle at int() of its surface coordinates (positive, so floor): the
# drawn centre is on average half a pixel below (image rows grow downwards) and left of the true one.
_ELBOW_CORRECTION = (-0.5, 0.5)
# A pixel within this much of the link colour in every channel is link (interior pixels are exact;
# this admits only the strongest anti-aliasing). Joint yellow, white and their blends are not link.
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
# Link 2's rays form a run of ~2 asin(half width / ray end) = 11.8 degrees (22-28 rays measured);
# link 1 leaves runs of at most 3 straggler rays beside the pivot circle: shorter runs are no arm.
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
    """Image (row, col) of the free end of link 2, read from an RGB frame's pixels only, or None
    when no pendulum is visible.

    Both links have the same colour and length, so the farthest link pixel from the pivot is not
    the tip when link 2 folds back. Instead: the elbow is the centre of the joint circle a link
    length from the pivot (the pivot's own circle sits at the screen centre); link 2 is the
    bundle of rays from the elbow that stay in link colour for almost a link length. Link 1's
    rays run into the pivot's yellow circle before that, unless link 2 is drawn over it, i.e.
    unless they are link 2's rays too; so the bundle is link 2's alone even when it lies along
    link 1 (folded: tip near the pivot). The tip is one link length from the elbow along the
    bundle's centre.

    Example:
        >>> with AcrobotRenderer() as renderer:
        ...     row, col = tip_pixel(renderer.render(0.0, 0.0).pixels)  # hanging straight down
        >>> round(height_from_tip_pixel(row, col), 1), round(col)
        (-2.0, 250)
        >>> tip_pixel(np.full(FRAME_SHAPE, 255, dtype=np.uint8)) is None
        True
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
    """Tip height (link lengths above the pivot) of an image position (row, col) in px.

    Only the row matters: ``(PIVOT_PIXEL[0] - row) / SCALE``; ``col`` is taken so that the
    result of ``tip_pixel`` can be passed as it comes.

    Example:
        >>> height_from_tip_pixel(PIVOT_PIXEL[0], 250.0), height_from_tip_pixel(PIVOT_PIXEL[0] - SCALE, 0.0)
        (0.0, 1.0)
    """
    return (PIVOT_PIXEL[0] - row) / SCALE


class AcrobotReader:
    """The simulated VLM's pixel reader for Acrobot (a ``vlmrl_cli.vlm.sim.MilestoneReader``):
    the label of the tip height read by ``tip_pixel``, None when no pendulum is visible.

    Example:
        >>> with AcrobotRenderer() as renderer:
        ...     frame = renderer.render(math.pi, 0.0)  # straight up
        >>> AcrobotReader().read(frame.pixels)
        'ABOVE_BAR'
    """

    name: str = "acrobot"
    milestones: Milestones = MILESTONES

    def read(self, pixels: np.ndarray) -> str | None:
        tip = tip_pixel(pixels)
        if tip is None:
            return None
        return label_of_height(height_from_tip_pixel(*tip))


class AcrobotCamera(CellCamera[tuple[int, int]]):
    """Renders Acrobot with both angles snapped to ``bins_per_joint`` equal bins; memoises per cell.

    An angle is wrapped into [-pi, pi) and shown at the centre of its bin, so a run shows at most
    ``bins_per_joint ** 2`` distinct frames (48 bins: 7.5 degrees, at most 2304 frames). As with
    ``shaping.camera.Camera``, ``renders`` counts calls to gymnasium's renderer and ``pixel_cache``
    is how many frames' pixels are kept (0.75 MB each); a dropped frame is drawn again on demand.

    Example:
        >>> cam = AcrobotCamera(bins_per_joint=48)
        >>> a, b = cam.view(0.01, 0.02), cam.view(0.02, 0.01)  # the same cell
        >>> a.key == b.key, cam.renders, a.features.shape
        (True, 1, (625,))
        >>> cam.cell_angles(0.01, 0.02) == cam.cell_angles(0.01 + 2 * math.pi, 0.02)
        True
        >>> cam.close()
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
        """Every (theta1, theta2) the camera can show: ``bins_per_joint ** 2`` of them, the bound on
        distinct frames (so on a real VLM's queries per run)."""
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
