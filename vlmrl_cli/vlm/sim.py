"""A SIMULATED stand-in for a small VLM (not a real model). See docs/getting-started.md."""

from __future__ import annotations

import dataclasses
import hashlib
import math
import time
from typing import Protocol, runtime_checkable

import numpy as np

from vlmrl_cli.core.fields import rules_of
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
    """A task's pixel reader: the label the pixels show (None: no agent).

    Optional attributes: ``model_base``, ``refusal`` and ``mcq_formats`` (templates with ``{label}``)."""

    name: str
    milestones: Milestones

    def read(self, pixels: np.ndarray) -> str | None: ...


@runtime_checkable
class NumberReader(MilestoneReader, Protocol):
    """A reader that also reads a number (a position, an angle): the float and box prompts too."""

    def estimate(self, pixels: np.ndarray, patch_px: int) -> float | None:
        """The noise-free reading, limited to a grid of ``patch_px`` pixels (None: no agent)."""

    def label_at(self, estimate: float, knobs: SimKnobs) -> str:
        """The label of a reading before flicker (a profile's knobs may widen a label's zone)."""

    def box_at(self, estimate: float) -> tuple[float, float, float, float]:
        """The agent's box (x0, y0, x1, y1, image pixels) where the reading puts it."""


NO_NUMBER = "I can only say which of the listed stages the image shows."
TASK_REFUSAL = "I'm sorry, but I cannot find what the question is about in this image."


def knobs_digest(knobs: SimKnobs) -> str:
    """8 hex digits naming the knobs that change answers; ``NEUTRAL_SIM_KNOBS`` count only off neutral."""
    shaping: tuple[object, ...] = (knobs.flicker, knobs.float_noise, knobs.box_noise_px, knobs.box_failure,
                                   knobs.patch_px, knobs.seed)
    added = sorted((k, v) for k, v in sim_identity(knobs).items() if k in NEUTRAL_SIM_KNOBS)
    if added:
        shaping = (*shaping, *added)
    return hashlib.sha256(repr(shaping).encode()).hexdigest()[:8]


def _step(index: int, n: int, left: bool) -> int:
    """The neighbouring label index, turned back at the ends."""
    step = -1 if left else 1
    if not 0 <= index + step < n:
        step = -step
    return index + step


class SimulatedVLM:
    """SIMULATED VLM (not a real model): answers the probe prompts from the pixels via ``reader``.

    MCQ: the label, a neighbour's with probability ``flicker``; FLOAT and BOX (``NumberReader``
    only): the patch-snapped reading with noise, a box that collapses with ``box_failure``. Answers
    are a pure function of (seed, prompt, image bytes), except with ``query_flicker > 0``: a fresh
    draw per query from a stream seeded by (seed, ``stream``), never cached (``stochastic``)."""

    name = "sim"
    simulated = True

    def __init__(self, reader: MilestoneReader, knobs: SimKnobs | None = None, stream: int = 0) -> None:
        knobs = knobs or SimKnobs()
        for f in dataclasses.fields(knobs):  # the rules the config schema applies, for knobs built in code
            value = getattr(knobs, f.name)
            for rule in rules_of(f):
                low, high = getattr(rule, "ge", -math.inf), getattr(rule, "le", math.inf)
                if isinstance(value, int | float) and not low <= value <= high:
                    raise ValueError(f"SimKnobs.{f.name}={value} must lie in [{low}, {high}].")
        self.knobs = knobs
        self.reader = reader
        self._numbers = reader if isinstance(reader, NumberReader) else None
        self._labels = reader.milestones.labels
        self._refusal: str = getattr(reader, "refusal", TASK_REFUSAL)
        self._mcq_formats: tuple[str, ...] = tuple(getattr(reader, "mcq_formats", _TASK_MCQ_FORMATS))
        # the knobs that shape the answers are in the model name, hence in every cache key
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
