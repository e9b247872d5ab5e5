"""The answer key of MountainCar-v0 frames, pure functions of the position ``x`` that mirror
``MountainCarEnv.render`` (600x400, y flipped); never an input of a VLM. Image coordinates are
(column, row) from the top left."""

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
# Upper edges (exclusive) of every zone but the last, in units of x (docs/method.md).
ZONE_EDGES: tuple[float, ...] = (-0.90, -0.60, -0.40, 0.0, GOAL_POSITION)


def track_height(x: float) -> float:
    """Track height (world units) at position ``x``: ``0.45 sin(3x) + 0.55``."""
    return math.sin(3 * x) * 0.45 + 0.55


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


def _pose(x: float) -> tuple[float, float, float]:
    """The car's angle (radians) and base point in drawing coordinates."""
    return math.cos(3 * x), (x - MIN_POSITION) * SCALE, CLEARANCE + track_height(x) * SCALE


def car_body_corners_px(x: float) -> np.ndarray:
    """The car body's four corners in image coordinates, shape (4, 2) as (column, row)."""
    angle, base_x, base_y = _pose(x)
    left, right, top, bottom = -CAR_WIDTH / 2, CAR_WIDTH / 2, CAR_HEIGHT, 0
    corners = []
    for cx, cy in ((left, bottom), (left, top), (right, top), (right, bottom)):
        rx, ry = _rotate(cx, cy, angle)
        corners.append(_to_image(rx + base_x, ry + base_y))
    return np.asarray(corners, dtype=float)


def wheel_centres_px(x: float) -> np.ndarray:
    """The two wheel centres in image coordinates, shape (2, 2); gymnasium truncates to int."""
    angle, base_x, base_y = _pose(x)
    centres = []
    for cx in (CAR_WIDTH / 4, -CAR_WIDTH / 4):
        rx, ry = _rotate(cx, 0.0, angle)
        centres.append(_to_image(int(rx + base_x), int(ry + base_y)))
    return np.asarray(centres, dtype=float)


def car_box_px(x: float) -> tuple[float, float, float, float]:
    """Axis-aligned box (x0, y0, x1, y1) in image pixels around the car body and wheels, clipped to the frame."""
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
    """The answer key for one frame, in the units a VLM is asked for (a ``NumberTruth``)."""

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
        """Ground truth of the frame rendered at position ``x`` and ``velocity``."""
        return cls(
            x=float(x),
            velocity=float(velocity),
            centre_px=car_centre_px(x),
            box_px=car_box_px(x),
            zone=zone_of(x),
        )
