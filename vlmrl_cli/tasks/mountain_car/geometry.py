"""Ground truth for MountainCar-v0 frames, computed from gymnasium's renderer geometry.

Everything here mirrors ``gymnasium.envs.classic_control.mountain_car.MountainCarEnv.render``:
a 600x400 RGB frame, world x in [-1.2, 0.6] scaled to the frame width, the track height
``0.45 sin(3x) + 0.55`` scaled by the same factor, a 40x20 px car body raised 10 px above the
track and rotated by ``cos(3x)`` radians, two wheels of radius 8 px, the drawing flipped
vertically at the end. Image coordinates are (column, row) with the origin at the top left.

These are pure functions of the position ``x``; they are the *answer key* for the probe,
never an input of a VLM.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

MIN_POSITION = -1.2
MAX_POSITION = 0.6
GOAL_POSITION = 0.5
MAX_SPEED = 0.07
SCREEN_WIDTH = 600
SCREEN_HEIGHT = 400
SCALE = SCREEN_WIDTH / (MAX_POSITION - MIN_POSITION)  # pixels per unit of x
CAR_WIDTH = 40
CAR_HEIGHT = 20
CLEARANCE = 10
WHEEL_RADIUS = int(CAR_HEIGHT / 2.5)
VALLEY_X = -math.pi / 6  # lowest point of the track, about -0.5236


class Zone(StrEnum):
    """The semantic milestones of the multiple-choice prompt, left to right."""

    LEFT_PEAK = "LEFT_PEAK"
    LEFT_SLOPE = "LEFT_SLOPE"
    BOTTOM = "BOTTOM"
    RIGHT_SLOPE = "RIGHT_SLOPE"
    NEAR_GOAL = "NEAR_GOAL"
    GOAL = "GOAL"


ZONES: tuple[Zone, ...] = tuple(Zone)
# Upper edges (exclusive) of every zone but the last, in units of x. BOTTOM is centred on the
# valley (-0.52), so the paper's "absolute valley" x=-0.50 is BOTTOM and its "lower left slope"
# x=-0.69 is LEFT_SLOPE; -0.40 is where the kinematic reward (Eq. 1) starts paying; 0.50 is
# the goal flag.
ZONE_EDGES: tuple[float, ...] = (-0.90, -0.60, -0.40, 0.0, GOAL_POSITION)


def track_height(x: float | np.ndarray) -> float | np.ndarray:
    """Track height (world units) at position ``x``: ``0.45 sin(3x) + 0.55``."""
    return np.sin(3 * np.asarray(x)) * 0.45 + 0.55 if isinstance(x, np.ndarray) else (
        math.sin(3 * x) * 0.45 + 0.55
    )


def zone_of(x: float, edges: tuple[float, ...] = ZONE_EDGES) -> Zone:
    """The semantic zone (the MCQ's correct answer) of position ``x``; ``edges``: the zones'
    upper edges (MountainCarContinuous-v0's GOAL starts at its flag, 0.45)."""
    for edge, zone in zip(edges, ZONES, strict=False):
        if x < edge:
            return zone
    return ZONES[-1]


def _rotate(px: float, py: float, angle: float) -> tuple[float, float]:
    c, s = math.cos(angle), math.sin(angle)
    return px * c - py * s, px * s + py * c


def _to_image(px: float, py: float) -> tuple[float, float]:
    """Drawing coordinates (y up, before gymnasium's flip) to image (column, row)."""
    return px, SCREEN_HEIGHT - 1 - py


def car_body_corners_px(x: float) -> np.ndarray:
    """The car body's four corners in image coordinates, shape (4, 2) as (column, row)."""
    angle = math.cos(3 * x)
    base_x = (x - MIN_POSITION) * SCALE
    base_y = CLEARANCE + float(track_height(x)) * SCALE
    left, right, top, bottom = -CAR_WIDTH / 2, CAR_WIDTH / 2, CAR_HEIGHT, 0
    corners = []
    for cx, cy in ((left, bottom), (left, top), (right, top), (right, bottom)):
        rx, ry = _rotate(cx, cy, angle)
        corners.append(_to_image(rx + base_x, ry + base_y))
    return np.asarray(corners, dtype=float)


def wheel_centres_px(x: float) -> np.ndarray:
    """The two wheel centres in image coordinates, shape (2, 2); gymnasium truncates to int."""
    angle = math.cos(3 * x)
    base_x = (x - MIN_POSITION) * SCALE
    base_y = CLEARANCE + float(track_height(x)) * SCALE
    centres = []
    for cx in (CAR_WIDTH / 4, -CAR_WIDTH / 4):
        rx, ry = _rotate(cx, 0.0, angle)
        centres.append(_to_image(int(rx + base_x), int(ry + base_y)))
    return np.asarray(centres, dtype=float)


def car_box_px(x: float) -> tuple[float, float, float, float]:
    """Axis-aligned box (x0, y0, x1, y1) in image pixels around the car body and wheels.

    Clipped to the frame: at the track's ends part of the car is drawn off-screen.
    """
    corners = car_body_corners_px(x)
    wheels = wheel_centres_px(x)
    x0 = min(corners[:, 0].min(), (wheels[:, 0] - WHEEL_RADIUS).min())
    x1 = max(corners[:, 0].max(), (wheels[:, 0] + WHEEL_RADIUS).max())
    y0 = min(corners[:, 1].min(), (wheels[:, 1] - WHEEL_RADIUS).min())
    y1 = max(corners[:, 1].max(), (wheels[:, 1] + WHEEL_RADIUS).max())
    x0, x1 = np.clip([x0, x1], 0, SCREEN_WIDTH - 1)
    y0, y1 = np.clip([y0, y1], 0, SCREEN_HEIGHT - 1)
    return float(x0), float(y0), float(x1), float(y1)


def car_centre_px(x: float) -> tuple[float, float]:
    """Centre of the car body in image pixels (column, row)."""
    corners = car_body_corners_px(x)
    return float(corners[:, 0].mean()), float(corners[:, 1].mean())


def x_from_column(column: float) -> float:
    """Invert the horizontal scale: the position whose car base sits at image ``column``."""
    return column / SCALE + MIN_POSITION


@dataclass(frozen=True)
class GroundTruth:
    """The answer key for one frame, in the units a VLM is asked for (a ``NumberTruth`` of
    MountainCar's ``NumberProbe``: ``label`` is the zone's name)."""

    x: float
    velocity: float
    centre_px: tuple[float, float]
    box_px: tuple[float, float, float, float]
    zone: Zone

    @property
    def label(self) -> str:
        """The MCQ's correct answer: the zone's name."""
        return str(self.zone)

    @classmethod
    def of(cls, x: float, velocity: float = 0.0) -> GroundTruth:
        """Ground truth of the frame rendered at position ``x`` and ``velocity``.

        Example:
            >>> GroundTruth.of(-0.5).zone
            <Zone.BOTTOM: 'BOTTOM'>
            >>> GroundTruth.of(-0.69).zone
            <Zone.LEFT_SLOPE: 'LEFT_SLOPE'>
        """
        return cls(
            x=float(x),
            velocity=float(velocity),
            centre_px=car_centre_px(x),
            box_px=car_box_px(x),
            zone=zone_of(x),
        )
