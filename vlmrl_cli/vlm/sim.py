"""A SIMULATED stand-in for a small VLM: a task's pixel reader with a coarse patch grid and noise.

This is not a vision-language model and produces no evidence about one. It exists so that
every command runs end to end without a GPU and so that tests are fast and deterministic.
A task's ``MilestoneReader`` reads the label from the frame's pixels (never the environment
state, never ``frame.frame_id``); a ``NumberReader`` (MountainCar's) also reads a number from
them, snapped to a grid of ``patch_px`` pixels as a ViT sees the image through patches, and so
answers the float and box prompts too. The answers then carry the noise and the format failures
that Table 1 of the paper describes.
"""

from __future__ import annotations

import hashlib
import time
from typing import Protocol, runtime_checkable

import numpy as np

from vlmrl_cli.frames.render import Frame
from vlmrl_cli.vlm.config import NEUTRAL_SIM_KNOBS, SimKnobs, sim_identity
from vlmrl_cli.vlm.prompts import Milestones, Prompt, PromptKind

MODEL_BASE = "pixel-reader-v1"

_FLOAT_FORMATS: tuple[str, ...] = (
    "{x:.3f}",
    "The car is at approximately {x:.2f}.",
    "x = {x:.2f}",
    "{x:.2f}",
)
_TASK_MCQ_FORMATS: tuple[str, ...] = ("{label}", "Choice = {label}", "{label}.", "The image shows {label}.")


class MilestoneReader(Protocol):
    """A task's pixel reader (``Task.reader``): the milestone label a frame shows, read from its
    pixels only, or None when the picture shows no agent. ``name`` goes into the simulated
    model's name, so that cached answers of two tasks never mix.

    A reader may also set ``model_base`` (the model name before the knobs' digest; default
    ``pixel-reader-v1-<name>``), ``refusal`` (the answer when it finds no agent) and
    ``mcq_formats`` (templates of an MCQ answer, each with ``{label}``)."""

    name: str
    milestones: Milestones

    def read(self, pixels: np.ndarray) -> str | None: ...


@runtime_checkable
class NumberReader(Protocol):
    """A reader that also reads a number from the pixels (a position, an angle), so the
    simulated VLM answers the task's float and box prompts (``Task.numbers``) as well: Table 1's
    rows I and II. Its MCQ answer is the label of the same patch-limited reading."""

    name: str
    milestones: Milestones

    def read(self, pixels: np.ndarray) -> str | None: ...

    def estimate(self, pixels: np.ndarray, patch_px: int) -> float | None:
        """The noise-free reading, limited to a grid of ``patch_px`` pixels (None: no agent)."""
        ...

    def label_at(self, estimate: float, knobs: SimKnobs) -> str:
        """The label of a reading before flicker (a profile's knobs may widen a label's zone)."""
        ...

    def box_at(self, estimate: float) -> tuple[float, float, float, float]:
        """The agent's box (x0, y0, x1, y1, image pixels) where the reading puts it."""
        ...


NO_NUMBER = "I can only say which of the listed stages the image shows."
TASK_REFUSAL = "I'm sorry, but I cannot find what the question is about in this image."


def knobs_digest(knobs: SimKnobs) -> str:
    """8 hex digits identifying the knobs that change answers (latency does not), and the profile.

    The knobs added with the profiles count only when they leave their neutral value, so the
    default profile keeps the digest (and the cached answers) it had before they existed.

    Example:
        >>> knobs_digest(SimKnobs()) == knobs_digest(SimKnobs(latency_s=1.0)) != knobs_digest(SimKnobs(seed=1))
        True
        >>> knobs_digest(SimKnobs()) != knobs_digest(SimKnobs(float_anchor=0.38))
        True
    """
    shaping: tuple[object, ...] = (knobs.flicker, knobs.float_noise, knobs.box_noise_px, knobs.box_failure,
                                   knobs.patch_px, knobs.seed)
    added = sorted((k, v) for k, v in sim_identity(knobs).items() if k in NEUTRAL_SIM_KNOBS)
    if added:
        shaping = (*shaping, *added)
    return hashlib.sha256(repr(shaping).encode()).hexdigest()[:8]


def _step(index: int, n: int, left: bool) -> int:
    """The index one step left (or right) of ``index`` among ``n`` labels, turned back at the ends."""
    step = -1 if left else 1
    if not 0 <= index + step < n:
        step = -step
    return index + step


class SimulatedVLM:
    """SIMULATED VLM (not a real model): answers the probe prompts from the pixels, through the
    task's ``reader``.

    MCQ: the reader's label, with probability ``flicker`` a neighbouring label (in the task's
    label order). With a ``NumberReader``, also FLOAT: the patch-snapped reading (or
    ``float_anchor`` when set: a reading stuck on one value) plus Gaussian noise (std
    ``float_noise``, the task's units), in one of a few chatty formats; BOX: with probability
    ``box_failure`` a format collapse ``"Error [0, 0, 0, 0]"``, else the agent's box at the
    reading (or at ``box_anchor_x``) with corner jitter (std ``box_noise_px``). Another reader
    gets no number (a format failure). No agent in the pixels: a refusal. The knobs' units are
    the reader's (a task's ``NumberReader`` reads a position, an angle); named sets of them are
    the generic ``SIM_PROFILES`` (vlm/config.py) and a task's own (``Task.sim_profiles``).

    Answers are a pure function of (seed, prompt text, image bytes): the response cache and
    replay transcripts rely on that. The one exception is ``query_flicker > 0``: then each MCQ
    answer is also moved to a neighbouring label with that probability by a draw from a stream
    seeded by ``(seed, stream)`` (``stream``: the training run's seed), fresh at every query, so
    the VLM is ``stochastic`` and its client caches nothing.

    Example:
        >>> from vlmrl_cli.frames.render import Frame
        >>> from vlmrl_cli.vlm.prompts import Milestones, mcq_prompt
        >>> class Lit:  # a toy reader: is the picture bright?
        ...     name, milestones = "lit", Milestones(("DARK", "LIT"), mcq_prompt("Lit?", ("DARK", "LIT")))
        ...     def read(self, pixels): return "LIT" if pixels.mean() > 127 else "DARK"
        >>> vlm = SimulatedVLM(Lit(), SimKnobs(flicker=0.0))
        >>> frame = Frame.from_pixels(np.full((8, 8, 3), 255, np.uint8))
        >>> vlm.answer(Lit.milestones.prompt, frame) in {"LIT", "Choice = LIT", "LIT.", "The image shows LIT."}
        True
        >>> vlm.model.startswith("pixel-reader-v1-lit/")
        True
    """

    name = "sim"
    simulated = True

    def __init__(self, reader: MilestoneReader, knobs: SimKnobs | None = None, stream: int = 0) -> None:
        knobs = knobs or SimKnobs()
        for prob_name in ("flicker", "box_failure", "query_flicker"):
            value = getattr(knobs, prob_name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"SimKnobs.{prob_name}={value} is a probability; pass a value in [0, 1].")
        if knobs.float_noise < 0 or knobs.box_noise_px < 0 or knobs.latency_s < 0:
            raise ValueError("SimKnobs noise and latency must be >= 0.")
        if knobs.mcq_bottom_halfwidth is not None and knobs.mcq_bottom_halfwidth < 0:
            raise ValueError(f"SimKnobs.mcq_bottom_halfwidth={knobs.mcq_bottom_halfwidth} must be >= 0 (a distance "
                             "in the reader's units).")
        if knobs.patch_px < 1:
            raise ValueError(f"SimKnobs.patch_px={knobs.patch_px} must be >= 1 pixel.")
        self.knobs = knobs
        self.reader = reader
        self._numbers = reader if isinstance(reader, NumberReader) else None
        self._labels = reader.milestones.labels
        self._refusal: str = getattr(reader, "refusal", TASK_REFUSAL)
        self._mcq_formats: tuple[str, ...] = tuple(getattr(reader, "mcq_formats", _TASK_MCQ_FORMATS))
        # The response cache keys on (backend, model, prompt, image): the knobs that shape the
        # answers go into the model name so that a cached answer never outlives its knobs.
        base = getattr(reader, "model_base", f"{MODEL_BASE}-{reader.name}")
        self.model = f"{base}/{knobs_digest(knobs)}"
        self.stochastic = knobs.query_flicker > 0
        self._draws = np.random.default_rng([knobs.seed, stream, 0x71F1])  # query_flicker only

    def _rng(self, prompt: Prompt, frame: Frame) -> np.random.Generator:
        blob = "\x1f".join((str(self.knobs.seed), prompt.text, frame.sha256)).encode()
        return np.random.default_rng(int.from_bytes(hashlib.sha256(blob).digest()[:8], "little"))

    def answer(self, prompt: Prompt, frame: Frame) -> str:
        if self.knobs.latency_s > 0:
            time.sleep(self.knobs.latency_s)
        numbers = self._numbers
        if numbers is None:
            label = self.reader.read(frame.pixels)
            if label is None:
                return self._refusal
            if prompt.kind is not PromptKind.MCQ:
                return NO_NUMBER
            return self._mcq(label, self._rng(prompt, frame))
        estimate = numbers.estimate(frame.pixels, self.knobs.patch_px)
        if estimate is None:
            return self._refusal
        rng = self._rng(prompt, frame)
        if prompt.kind is PromptKind.FLOAT:
            return self._float(estimate, rng)
        if prompt.kind is PromptKind.BOX:
            return self._box(numbers, estimate, rng)
        return self._mcq(numbers.label_at(estimate, self.knobs), rng)

    def _float(self, estimate: float, rng: np.random.Generator) -> str:
        read = estimate if self.knobs.float_anchor is None else self.knobs.float_anchor
        value = read + rng.normal(0.0, self.knobs.float_noise) if self.knobs.float_noise > 0 else read
        template = _FLOAT_FORMATS[int(rng.integers(len(_FLOAT_FORMATS)))]
        if self.knobs.float_anchor is not None:
            template = _FLOAT_FORMATS[0]  # a stuck reading comes as a bare number (Table 1: 0.378, 0.386)
        return template.format(x=value)

    def _box(self, numbers: NumberReader, estimate: float, rng: np.random.Generator) -> str:
        if rng.random() < self.knobs.box_failure:
            return "Error [0, 0, 0, 0]"
        at = estimate if self.knobs.box_anchor_x is None else self.knobs.box_anchor_x
        box = np.asarray(numbers.box_at(at))
        if self.knobs.box_noise_px > 0:
            box = box + rng.normal(0.0, self.knobs.box_noise_px, size=4)
        # a model that answers at all keeps the corner order; jitter may not swap them
        x0, x1 = sorted((round(float(box[0])), round(float(box[2]))))
        y0, y1 = sorted((round(float(box[1])), round(float(box[3]))))
        return f"[{x0}, {y0}, {x1}, {y1}]"

    def _mcq(self, label: str, rng: np.random.Generator) -> str:
        labels = self._labels
        index = labels.index(label)
        if rng.random() < self.knobs.flicker:
            index = _step(index, len(labels), rng.random() < 0.5)
        if self.stochastic and self._draws.random() < self.knobs.query_flicker:
            index = _step(index, len(labels), self._draws.random() < 0.5)
        template = self._mcq_formats[int(rng.integers(len(self._mcq_formats)))]
        return template.format(label=labels[index])

    def close(self) -> None:
        """Nothing to release."""
