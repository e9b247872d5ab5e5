"""A SIMULATED stand-in for a small VLM: a pixel reader with a coarse patch grid and noise.

This is not a vision-language model and produces no evidence about one. It exists so that
every command runs end to end without a GPU and so that tests are fast and deterministic.
It reads the car only from the frame's pixels (never the environment state, never
``frame.frame_id``): gymnasium draws both wheels in exactly (128, 128, 128), so the wheels'
centre column locates the car. Limited spatial resolution is modelled by snapping that column
to a grid of ``patch_px`` pixels, as a ViT sees the image through patches; the answers then
carry the noise and the format failures that Table 1 of the paper describes.
"""

from __future__ import annotations

import hashlib
import time
from typing import Protocol

import numpy as np

from vlmrl_cli.frames import geometry
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.vlm.config import NEUTRAL_SIM_KNOBS, SimKnobs, sim_identity
from vlmrl_cli.vlm.prompts import Milestones, Prompt, PromptKind

WHEEL_GREY = 128
# Columns with at least this many wheel-grey pixels are wheel, not anti-aliasing strays.
_MIN_COLUMN_PIXELS = 3
# Even half off-screen one wheel leaves ~8 solid columns; fewer means no car.
_MIN_WHEEL_COLUMNS = 4
MODEL_BASE = "pixel-reader-v1"
REFUSAL = "I'm sorry, but I cannot find a car in this image."

_FLOAT_FORMATS: tuple[str, ...] = (
    "{x:.3f}",
    "The car is at approximately {x:.2f}.",
    "x = {x:.2f}",
    "{x:.2f}",
)
_MCQ_FORMATS: tuple[str, ...] = ("{label}", "Choice = {label}", "{label}.", "The car is at {label}.")
_TASK_MCQ_FORMATS: tuple[str, ...] = ("{label}", "Choice = {label}", "{label}.", "The image shows {label}.")


class MilestoneReader(Protocol):
    """Another task's pixel reader (a task plug-in supplies it): the milestone label a frame
    shows, read from its pixels only, or None when the picture shows no agent. ``name`` goes into
    the simulated model's name, so that cached answers of two tasks never mix."""

    name: str
    milestones: Milestones

    def read(self, pixels: np.ndarray) -> str | None: ...


NO_NUMBER = "I can only say which of the listed stages the image shows."
TASK_REFUSAL = "I'm sorry, but I cannot find what the question is about in this image."


def knobs_digest(knobs: SimKnobs) -> str:
    """8 hex digits identifying the knobs that change answers (latency does not), and the profile.

    The knobs added with the profiles count only when they leave their neutral value, so the
    default profile keeps the digest (and the cached answers) it had before they existed.

    Example:
        >>> knobs_digest(SimKnobs()) == knobs_digest(SimKnobs(latency_s=1.0)) != knobs_digest(SimKnobs(seed=1))
        True
        >>> knobs_digest(SimKnobs()) != knobs_digest(SimKnobs.of_profile("llava-table1"))
        True
    """
    shaping: tuple[object, ...] = (knobs.flicker, knobs.float_noise, knobs.box_noise_px, knobs.box_failure,
                                   knobs.patch_px, knobs.seed)
    added = sorted((k, v) for k, v in sim_identity(knobs).items() if k in NEUTRAL_SIM_KNOBS)
    if added:
        shaping = (*shaping, *added)
    return hashlib.sha256(repr(shaping).encode()).hexdigest()[:8]


def wheel_column(pixels: np.ndarray) -> float | None:
    """Centre column (image px) of the car's wheels in an RGB frame of shape (H, W, 3), or None.

    Only exact (128, 128, 128) pixels count, and only in columns holding several of them:
    anti-aliasing of the track and the flag leaves single stray pixels of that grey.
    """
    flat = np.ascontiguousarray(pixels).reshape(-1, 3)
    # one channel first (~4x faster than all three), on a contiguous copy of it
    (hits,) = np.nonzero(np.ascontiguousarray(flat[:, 0]) == WHEEL_GREY)
    grey = (flat[hits, 1] == WHEEL_GREY) & (flat[hits, 2] == WHEEL_GREY)
    counts = np.bincount(hits[grey] % pixels.shape[1], minlength=pixels.shape[1])
    # a wheel disc's columns hold up to 2 * radius pixels; both discs lose the same sparse rims
    # to this cut, so the midpoint below is unchanged
    solid = np.nonzero(counts >= _MIN_COLUMN_PIXELS)[0]
    if solid.size < _MIN_WHEEL_COLUMNS:
        return None
    # the two wheels sit symmetrically about the car's base point, so the midpoint of their
    # extent is the base column
    return (float(solid.min()) + float(solid.max())) / 2.0


def snap_to_patch(column: float, patch_px: int) -> float:
    """Centre of the ``patch_px``-wide patch that holds ``column`` (image px)."""
    if patch_px <= 1:
        return column
    return (np.floor(column / patch_px) + 0.5) * patch_px


def _neighbour(index: int, left: bool) -> int:
    """The zone index one step left (or right) of ``index``, turned back at the track's ends."""
    return _step(index, len(geometry.ZONES), left)


def _step(index: int, n: int, left: bool) -> int:
    """The index one step left (or right) of ``index`` among ``n`` labels, turned back at the ends."""
    step = -1 if left else 1
    if not 0 <= index + step < n:
        step = -step
    return index + step


class SimulatedVLM:
    """SIMULATED VLM (not a real model): answers the three probe prompts from the pixels.

    FLOAT: the patch-snapped x estimate (or ``float_anchor`` when set: a reading stuck on one
    value) plus Gaussian noise (std ``float_noise``, x units), in one of a few chatty formats.
    BOX: with probability ``box_failure`` a format collapse ``"Error [0, 0, 0, 0]"``, else the
    car's box at the estimate (or at ``box_anchor_x``) with corner jitter (std ``box_noise_px``).
    MCQ: the zone of the estimate (BOTTOM within ``mcq_bottom_halfwidth`` of the valley when
    set: a widened dead zone), with probability ``flicker`` a neighbouring label. No car in the
    pixels: a refusal. ``SIM_PROFILES`` (vlm/config.py) names sets of these knobs.

    Answers are a pure function of (seed, prompt text, image bytes): the response cache and
    replay transcripts rely on that. The one exception is ``query_flicker > 0``: then each MCQ
    answer is also moved to a neighbouring label with that probability by a draw from a stream
    seeded by ``(seed, stream)`` (``stream``: the training run's seed), fresh at every query, so
    the VLM is ``stochastic`` and its client caches nothing.

    Example:
        >>> from vlmrl_cli.frames.render import FrameRenderer
        >>> from vlmrl_cli.vlm.prompts import PROMPTS, PromptKind
        >>> with FrameRenderer() as renderer:
        ...     frame = renderer.render(-0.5)
        >>> vlm = SimulatedVLM(SimKnobs(flicker=0.0))
        >>> vlm.answer(PROMPTS[PromptKind.MCQ], frame) in {"BOTTOM", "Choice = BOTTOM", "BOTTOM.",
        ...                                               "The car is at BOTTOM."}
        True
    """

    name = "sim"
    simulated = True

    def __init__(self, knobs: SimKnobs | None = None, stream: int = 0, reader: MilestoneReader | None = None) -> None:
        knobs = knobs or SimKnobs()
        for prob_name in ("flicker", "box_failure", "query_flicker"):
            value = getattr(knobs, prob_name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"SimKnobs.{prob_name}={value} is a probability; pass a value in [0, 1].")
        if knobs.float_noise < 0 or knobs.box_noise_px < 0 or knobs.latency_s < 0:
            raise ValueError("SimKnobs noise and latency must be >= 0.")
        if knobs.mcq_bottom_halfwidth is not None and knobs.mcq_bottom_halfwidth < 0:
            raise ValueError(f"SimKnobs.mcq_bottom_halfwidth={knobs.mcq_bottom_halfwidth} must be >= 0 (x units).")
        if knobs.patch_px < 1:
            raise ValueError(f"SimKnobs.patch_px={knobs.patch_px} must be >= 1 pixel.")
        self.knobs = knobs
        # The response cache keys on (backend, model, prompt, image): the knobs that shape the
        # answers go into the model name so that a cached answer never outlives its knobs.
        self.reader = reader
        base = MODEL_BASE if reader is None else f"{MODEL_BASE}-{reader.name}"
        self.model = f"{base}/{knobs_digest(knobs)}"
        self.stochastic = knobs.query_flicker > 0
        self._draws = np.random.default_rng([knobs.seed, stream, 0x71F1])  # query_flicker only

    def _rng(self, prompt: Prompt, frame: Frame) -> np.random.Generator:
        blob = "\x1f".join((str(self.knobs.seed), prompt.text, frame.sha256)).encode()
        return np.random.default_rng(int.from_bytes(hashlib.sha256(blob).digest()[:8], "little"))

    def estimate_x(self, frame: Frame) -> float | None:
        """The noise-free, patch-limited position estimate read from the pixels (x units)."""
        column = wheel_column(frame.pixels)
        if column is None:
            return None
        x = geometry.x_from_column(snap_to_patch(column, self.knobs.patch_px))
        return float(np.clip(x, geometry.MIN_POSITION, geometry.MAX_POSITION))

    def answer(self, prompt: Prompt, frame: Frame) -> str:
        if self.knobs.latency_s > 0:
            time.sleep(self.knobs.latency_s)
        if self.reader is not None:
            return self._task_answer(prompt, frame, self.reader)
        x_est = self.estimate_x(frame)
        if x_est is None:
            return REFUSAL
        rng = self._rng(prompt, frame)
        if prompt.kind is PromptKind.FLOAT:
            return self._float(x_est, rng)
        if prompt.kind is PromptKind.BOX:
            return self._box(x_est, rng)
        return self._mcq(x_est, rng)

    def _float(self, x_est: float, rng: np.random.Generator) -> str:
        read = x_est if self.knobs.float_anchor is None else self.knobs.float_anchor
        value = read + rng.normal(0.0, self.knobs.float_noise) if self.knobs.float_noise > 0 else read
        template = _FLOAT_FORMATS[int(rng.integers(len(_FLOAT_FORMATS)))]
        if self.knobs.float_anchor is not None:
            template = _FLOAT_FORMATS[0]  # a stuck reading comes as a bare number (Table 1: 0.378, 0.386)
        return template.format(x=value)

    def _box(self, x_est: float, rng: np.random.Generator) -> str:
        if rng.random() < self.knobs.box_failure:
            return "Error [0, 0, 0, 0]"
        at = x_est if self.knobs.box_anchor_x is None else self.knobs.box_anchor_x
        box = np.asarray(geometry.car_box_px(at))
        if self.knobs.box_noise_px > 0:
            box = box + rng.normal(0.0, self.knobs.box_noise_px, size=4)
        # a model that answers at all keeps the corner order; jitter may not swap them
        x0, x1 = sorted((round(float(box[0])), round(float(box[2]))))
        y0, y1 = sorted((round(float(box[1])), round(float(box[3]))))
        return f"[{x0}, {y0}, {x1}, {y1}]"

    def _mcq(self, x_est: float, rng: np.random.Generator) -> str:
        index = geometry.ZONES.index(self.zone(x_est))
        if rng.random() < self.knobs.flicker:
            index = _neighbour(index, rng.random() < 0.5)
        if self.stochastic and self._draws.random() < self.knobs.query_flicker:
            index = _neighbour(index, self._draws.random() < 0.5)
        template = _MCQ_FORMATS[int(rng.integers(len(_MCQ_FORMATS)))]
        return template.format(label=geometry.ZONES[index].value)

    def _task_answer(self, prompt: Prompt, frame: Frame, reader: MilestoneReader) -> str:
        """Another task's answers: MCQ from ``reader`` with the same flicker, format mix and
        query flicker as MountainCar's; a float or box prompt gets no number (a format failure)."""
        label = reader.read(frame.pixels)
        if label is None:
            return TASK_REFUSAL
        if prompt.kind is not PromptKind.MCQ:
            return NO_NUMBER
        rng = self._rng(prompt, frame)
        labels = reader.milestones.labels
        index = labels.index(label)
        if rng.random() < self.knobs.flicker:
            index = _step(index, len(labels), rng.random() < 0.5)
        if self.stochastic and self._draws.random() < self.knobs.query_flicker:
            index = _step(index, len(labels), self._draws.random() < 0.5)
        template = _TASK_MCQ_FORMATS[int(rng.integers(len(_TASK_MCQ_FORMATS)))]
        return template.format(label=labels[index])

    def zone(self, x_est: float) -> geometry.Zone:
        """The label the simulated classifier gives an estimate before flicker: its true zone, or
        BOTTOM anywhere within ``mcq_bottom_halfwidth`` of the valley."""
        width = self.knobs.mcq_bottom_halfwidth
        if width is not None and abs(x_est - geometry.VALLEY_X) <= width:
            return geometry.Zone.BOTTOM
        return geometry.zone_of(x_est)

    def close(self) -> None:
        """Nothing to release."""
