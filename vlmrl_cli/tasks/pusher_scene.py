"""Pusher-v5's scene: milestones of the puck-goal and fingertip-puck distances, ground truth,
MuJoCo's offscreen renderer (cheap flags, 80 x 80 px), the pixel reader (colour blobs mapped back
onto the table) and the camera, which snaps the fingertip and puck to a grid. Positions are world
metres. See docs/tasks.md, "Pusher-v5"."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from vlmrl_cli.frames.render import Frame
from vlmrl_cli.shaping.camera import CellCamera, FrameView
from vlmrl_cli.vlm.prompts import Milestones, mcq_prompt

SIDE = 80  # px
FRAME_SHAPE = (SIDE, SIDE, 3)
SUCCESS_M = 0.05  # puck within this of the goal in the plane: success (and ON_TARGET)
NEAR_TARGET_M = 0.12
AT_PUCK_M = 0.10
# The reader's edge for AT_PUCK: a fingertip at the puck hides part of it, moving its visible centre ~1.5 cm
READ_AT_PUCK_M = 0.115
GOAL_XY = (0.45, -0.05)  # Pusher-v5's goal body (its slide joints stay at 0)
PUCK_Z = -0.275  # the puck's centre height (its body sits on the table)
PUCK_TOP_Z = -0.225  # its top face (a cylinder of half-height 0.05): what the camera sees most of
GOAL_Z = -0.322  # the goal disc's top (2 mm thick, its body 4.8 cm below the puck's centre)
GOAL_RADIUS_M = 0.08
PUCK_RADIUS_M = 0.05
TIP_CELL_M = 0.03
PUCK_CELL_M = 0.02

LABELS: tuple[str, ...] = ("FAR_FROM_PUCK", "AT_PUCK", "NEAR_TARGET", "ON_TARGET")
POTENTIALS: tuple[tuple[str, float], ...] = (("FAR_FROM_PUCK", 0.0), ("AT_PUCK", 0.3), ("NEAR_TARGET", 0.6),
                                             ("ON_TARGET", 1.0))
MILESTONES = Milestones(LABELS, mcq_prompt(
    "This image shows a robot arm over a grey table, with a white puck, a red target disc and the arm's "
    "fingertip marked by a blue ball. FAR_FROM_PUCK: the fingertip is away from the puck and the puck is "
    "far from the target; AT_PUCK: the fingertip touches the puck; NEAR_TARGET: the puck is close to the "
    "target but not on it; ON_TARGET: the puck sits on the red target.", LABELS))

# The camera: MuJoCo's free camera (degrees, metres).
LOOKAT = (0.35, -0.2, -0.3)
DISTANCE = 1.6
AZIMUTH = 180.0
ELEVATION = -55.0
TIP_MARKER_GEOM = "tip_arml"  # one of the two finger spheres, moved to the fingertip point
TIP_RADIUS_M = 0.04
TIP_RGBA = (0.1, 0.3, 1.0, 1.0)
QUALITY_SLICES = 12  # MuJoCo's default 28: the puck a 12-gon, enough at 80 px
QUALITY_STACKS = 8  # default 16


def use_headless_gl() -> str:
    """``MUJOCO_GL`` for this process: the user's value, else ``egl`` (set before ``mujoco`` loads)."""
    return os.environ.setdefault("MUJOCO_GL", "egl")


def label_of(d_tp: float, d_pg: float, at_puck: float = AT_PUCK_M) -> str:
    """The milestone of a fingertip-puck distance ``d_tp`` (3D) and a puck-goal distance ``d_pg`` (2D), metres.

    Example:
        >>> label_of(0.5, 0.3), label_of(0.08, 0.3), label_of(0.5, 0.1), label_of(0.5, 0.049)
        ('FAR_FROM_PUCK', 'AT_PUCK', 'NEAR_TARGET', 'ON_TARGET')
    """
    if math.isnan(d_tp) or math.isnan(d_pg):
        raise ValueError("distances must not be NaN")
    if d_pg < SUCCESS_M:
        return "ON_TARGET"
    if d_pg < NEAR_TARGET_M:
        return "NEAR_TARGET"
    return "AT_PUCK" if d_tp < at_puck else "FAR_FROM_PUCK"


def distances(tip: np.ndarray, puck: np.ndarray, goal: np.ndarray) -> tuple[float, float]:
    """``(d_tp, d_pg)``: fingertip to puck in 3D, puck to goal in the plane (x, y).

    Example:
        >>> distances(np.array([0.0, 0.0, 0.1]), np.zeros(3), np.array([0.3, 0.4, -0.05]))
        (0.1, 0.5)
    """
    d_tp = float(np.linalg.norm(np.asarray(tip, dtype=float) - np.asarray(puck, dtype=float)))
    d_pg = float(np.linalg.norm(np.asarray(puck, dtype=float)[:2] - np.asarray(goal, dtype=float)[:2]))
    return d_tp, d_pg


def positions(sim: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The fingertip's, puck's and goal's world positions of a simulator, as its observation gives them."""
    return (np.array(sim.get_body_com("tips_arm")), np.array(sim.get_body_com("object")),
            np.array(sim.get_body_com("goal")))


def label_of_sim(sim: Any) -> str:
    """Ground truth: the milestone of a Pusher simulator (probes and tests only, never the VLM)."""
    return label_of(*distances(*positions(sim)))


@dataclass(frozen=True)
class TableCamera:
    """The fixed camera's pinhole projection: world point <-> continuous pixel (row, col), row 0 at the top.

    Example:
        >>> cam = TableCamera.fixed()
        >>> row, col = cam.pixel_of(np.array([*LOOKAT]))
        >>> round(row, 6), round(col, 6)
        (40.0, 40.0)
        >>> np.round(cam.on_plane(row, col, LOOKAT[2]), 6).tolist() == [*LOOKAT]
        True
    """

    position: tuple[float, float, float]
    forward: tuple[float, float, float]
    up: tuple[float, float, float]
    focal_px: float
    side: int

    @classmethod
    def fixed(cls, side: int = SIDE, fovy_deg: float = 45.0) -> TableCamera:
        """The task's camera (``fovy_deg``: the model's ``vis.global.fovy``)."""
        az, el = math.radians(AZIMUTH), math.radians(ELEVATION)
        forward = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        position = np.asarray(LOOKAT) - DISTANCE * forward
        up = np.array([-math.sin(el) * math.cos(az), -math.sin(el) * math.sin(az), math.cos(el)])
        focal = (side / 2) / math.tan(math.radians(fovy_deg) / 2)
        return cls(_triple(position), _triple(forward), _triple(up), focal, side)

    def _axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        forward, up = np.asarray(self.forward), np.asarray(self.up)
        return forward, up, np.cross(forward, up)

    def pixel_of(self, point: np.ndarray) -> tuple[float, float]:
        """(row, col) where the world ``point`` shows."""
        forward, up, right = self._axes()
        v = np.asarray(point, dtype=float) - np.asarray(self.position)
        depth = float(v @ forward)
        half = self.side / 2
        return half - self.focal_px * float(v @ up) / depth, half + self.focal_px * float(v @ right) / depth

    def disc_axes_px(self, radius: float, centre: tuple[float, float, float] = (*GOAL_XY, GOAL_Z)
                     ) -> tuple[float, float]:
        """The half axes (rows, cols) in px of a flat disc of ``radius`` lying at ``centre``."""
        c = np.asarray(centre, dtype=float)
        row0, col0 = self.pixel_of(c)
        along_x = self.pixel_of(c + np.array([radius, 0.0, 0.0]))
        along_y = self.pixel_of(c + np.array([0.0, radius, 0.0]))
        return max(abs(along_x[0] - row0), abs(along_y[0] - row0)), max(abs(along_x[1] - col0), abs(along_y[1] - col0))

    def on_plane(self, row: float, col: float, z: float) -> np.ndarray:
        """The world point at height ``z`` that shows at (row, col)."""
        forward, up, right = self._axes()
        half = self.side / 2
        ray = forward + ((col - half) / self.focal_px) * right - ((row - half) / self.focal_px) * up
        t = (z - self.position[2]) / ray[2]
        return np.asarray(self.position) + t * ray


def _triple(v: np.ndarray) -> tuple[float, float, float]:
    return float(v[0]), float(v[1]), float(v[2])


CAMERA = TableCamera.fixed()

# --- the pixel reader --------------------------------------------------------------------------
# Colour tests on the lit picture: the table and arm are grey (r = g = b), the puck white and lit
# (every channel high), the goal pure red, the fingertip marker blue. A blob needs a few pixels.
_MIN_PIXELS = 2


def _blob(mask: np.ndarray) -> tuple[float, float] | None:
    rows, cols = np.nonzero(mask)
    if rows.size < _MIN_PIXELS:
        return None
    return float(rows.mean()) + 0.5, float(cols.mean()) + 0.5


def colour_masks(pixels: np.ndarray) -> dict[str, np.ndarray]:
    """Boolean masks of the fingertip marker's blue (``tip``), the puck's white and the goal's red."""
    if pixels.ndim != 3 or pixels.shape[2] != 3:
        raise ValueError(f"expected an RGB frame (H, W, 3), got {pixels.shape}")
    p = pixels.astype(np.int16)
    r, g, b = p[..., 0], p[..., 1], p[..., 2]
    return {"tip": (b > 60) & (b > 2 * r) & (b > g + 30),
            "puck": (r > 170) & (g > 170) & (b > 170) & (np.abs(r - b) < 30),
            "goal": (r > 90) & (r > 3 * g) & (r > 3 * b)}


_OFFSETS = np.arange(-3.0, 3.01, 0.5)  # px: where a disc's outline is tried around its blob's centroid


def _disc_centre(target: np.ndarray, neutral: np.ndarray, axes: tuple[float, float]) -> tuple[float, float]:
    """The centre (row, col) of a disc whose visible pixels are ``target``: its outline (half axes
    ``axes`` px) placed to cover the most of them and the least else (``neutral`` pixels: neither)."""
    rows, cols = np.nonzero(target)
    r0, c0 = float(rows.mean()) + 0.5, float(cols.mean()) + 0.5
    a_row, a_col = axes
    top, left = max(int(r0 - a_row - 4), 0), max(int(c0 - a_col - 4), 0)
    window = (slice(top, min(int(r0 + a_row) + 5, target.shape[0])),
              slice(left, min(int(c0 + a_col) + 5, target.shape[1])))
    vote = np.where(target[window], 1.0, np.where(neutral[window], 0.0, -1.0)).reshape(-1)
    yy, xx = np.mgrid[window]
    yy, xx = yy.reshape(-1) + 0.5, xx.reshape(-1) + 0.5
    centres_r = (r0 + _OFFSETS)[:, None, None]
    centres_c = (c0 + _OFFSETS)[None, :, None]
    inside = ((yy - centres_r) / a_row) ** 2 + ((xx - centres_c) / a_col) ** 2 <= 1.0  # (R, C, pixels)
    missed = target[window].reshape(-1)
    score = (inside * vote).sum(axis=2) - (~inside * missed).sum(axis=2)
    i, j = np.unravel_index(int(np.argmax(score)), score.shape)
    return r0 + float(_OFFSETS[i]), c0 + float(_OFFSETS[j])


def read_distances(pixels: np.ndarray, camera: TableCamera = CAMERA) -> tuple[float | None, float | None]:
    """``(d_tp, d_pg)`` read from the pixels (None where an object is not in sight), the fingertip taken
    at the puck's centre height (one camera sees no depth)."""
    masks = colour_masks(pixels)
    puck_px = _blob(masks["puck"])
    if puck_px is None:
        return None, None
    puck_axes = camera.disc_axes_px(PUCK_RADIUS_M, (*GOAL_XY, PUCK_TOP_Z))
    puck = camera.on_plane(*_disc_centre(masks["puck"], masks["tip"], puck_axes), PUCK_TOP_Z)
    d_pg = None
    if masks["goal"].sum() >= _MIN_PIXELS:
        goal_px = _disc_centre(masks["goal"], masks["puck"] | masks["tip"], camera.disc_axes_px(GOAL_RADIUS_M))
        goal = camera.on_plane(*goal_px, GOAL_Z)
        d_pg = float(np.linalg.norm(puck[:2] - goal[:2]))
    d_tp = None
    tip_px = _blob(masks["tip"])
    if tip_px is not None:
        tip = camera.on_plane(*tip_px, PUCK_Z)
        d_tp = float(np.linalg.norm(tip[:2] - puck[:2]))
    return d_tp, d_pg


def read_label(pixels: np.ndarray) -> str | None:
    """The milestone a frame shows, from its pixels only (None: neither puck nor target in sight); a
    hidden goal reads as far, a hidden fingertip as away, a hidden puck as the fingertip at it."""
    d_tp, d_pg = read_distances(pixels)
    if d_tp is None and d_pg is None:  # no puck in sight: the arm hides it, so the hand is over it
        return "AT_PUCK" if _blob(colour_masks(pixels)["goal"]) is not None else None
    return label_of(math.inf if d_tp is None else d_tp, math.inf if d_pg is None else d_pg, READ_AT_PUCK_M)


class PusherReader:
    """The simulated VLM's pixel reader for Pusher (a ``MilestoneReader``): ``read_label``."""

    name = "pusher"
    milestones = MILESTONES

    def read(self, pixels: np.ndarray) -> str | None:
        return read_label(pixels)


# --- the renderer and the camera -----------------------------------------------------------------


class PusherRenderer:
    """Draws Pusher-v5 states (``qpos``) off screen, on a copy of the model with the fingertip marker."""

    def __init__(self, model: Any) -> None:
        import copy

        use_headless_gl()
        import mujoco

        self.model = copy.deepcopy(model)
        self.model.vis.quality.offsamples = 0  # cheap frames: see docs/tasks.md
        self.model.vis.quality.numslices = QUALITY_SLICES
        self.model.vis.quality.numstacks = QUALITY_STACKS
        marker = self.model.geom(TIP_MARKER_GEOM)  # drawn at the fingertip's point (the body's origin)
        marker.pos[:] = 0.0
        marker.size[0] = TIP_RADIUS_M
        marker.rgba[:] = TIP_RGBA
        self.data = mujoco.MjData(self.model)
        self._renderer = mujoco.Renderer(self.model, SIDE, SIDE)
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self._camera.lookat[:] = LOOKAT
        self._camera.distance, self._camera.azimuth, self._camera.elevation = DISTANCE, AZIMUTH, ELEVATION
        self._off = (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION,
                     mujoco.mjtRndFlag.mjRND_SKYBOX)

    def render(self, qpos: np.ndarray, sha256: str | None = None) -> Frame:
        import mujoco

        self.data.qpos[:] = qpos
        mujoco.mj_forward(self.model, self.data)  # the lights' and bodies' poses
        self._renderer.update_scene(self.data, camera=self._camera)
        for flag in self._off:
            self._renderer.scene.flags[flag] = 0
        return Frame.drawn(self._renderer.render(), sha256=sha256)

    def close(self) -> None:
        self._renderer.close()


Cell = tuple[int, ...]  # the fingertip's 3 grid indices, then the puck's 2 and the goal's 2


def cell_of(sim: Any) -> Cell:
    """The grid cell of a simulator: fingertip (``TIP_CELL_M``), puck and goal slides (``PUCK_CELL_M``)."""
    tip = sim.data.body("tips_arm").xpos
    qpos = sim.data.qpos
    return (*(math.floor(float(v) / TIP_CELL_M) for v in tip),
            *(round(float(v) / PUCK_CELL_M) for v in qpos[-4:]))


class PusherCamera(CellCamera[Cell]):
    """The task's camera: one frame per grid cell, the arm in the pose of the cell's first visit (kept,
    so a dropped frame is drawn again identically), the puck and goal at the cell's centre."""

    def __init__(self, pixel_cache: int = 256) -> None:
        super().__init__(pixel_cache)
        self._poses: dict[Cell, np.ndarray] = {}
        self._renderer: PusherRenderer | None = None
        self._model: Any = None

    def __deepcopy__(self, memo: dict[int, object]) -> PusherCamera:
        # One camera (one GL context) serves the envs of a run, as the oracle does; gymnasium's
        # RecordConstructorArgs deep-copies wrapper arguments, and a copy must keep sharing it.
        return self

    def _draw(self, cell: Cell, sha256: str | None) -> Frame:
        if self._renderer is None:
            self._renderer = PusherRenderer(self._model)
        return self._renderer.render(self._poses[cell], sha256=sha256)

    def look(self, sim: Any) -> FrameView:
        cell = cell_of(sim)
        view = self._views.get(cell)
        if view is not None:
            return view
        if self._model is None:
            self._model = sim.model
        pose = np.array(sim.data.qpos, dtype=np.float64)
        pose[-4:] = np.round(pose[-4:] / PUCK_CELL_M) * PUCK_CELL_M  # the goal's 0 stays 0
        self._poses[cell] = pose
        return self._view_of(cell)
