"""The prompt kinds of the taxonomy probe (paper Table 1) and a task's questions asked with them."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Protocol

from vlmrl_cli.core.fields import CARRIED
from vlmrl_cli.frames.render import Frame


class PromptKind(StrEnum):
    """Table 1's error taxonomy rows: I float regression, II box grounding, III semantic MCQ."""

    FLOAT = "float"
    BOX = "box"
    MCQ = "mcq"


@dataclass(frozen=True)
class Prompt:
    """A prompt kind and the exact text sent with the frame; an MCQ's ``options`` are never hashed.

    Example:
        >>> from vlmrl_cli.core.provenance import to_jsonable
        >>> p = mcq_prompt("Lit?", ("DARK", "LIT"))
        >>> p.options, sorted(to_jsonable(p))
        (('DARK', 'LIT'), ['kind', 'text'])
    """

    kind: PromptKind
    text: str
    options: tuple[str, ...] | None = field(default=None, metadata=CARRIED)

    def __post_init__(self) -> None:
        if self.options is not None and (self.kind is not PromptKind.MCQ or len(set(self.options)) < 2
                                         or len(set(self.options)) != len(self.options)):
            raise ValueError(f"only an MCQ prompt has options, at least two distinct ones, got {self.options}")


@dataclass(frozen=True)
class Milestones:
    """A task's MCQ vocabulary: its ``labels`` in order (flicker moves to a neighbour) and ``prompt``."""

    labels: tuple[str, ...]
    prompt: Prompt

    def __post_init__(self) -> None:
        if len(self.labels) < 2 or len(set(self.labels)) != len(self.labels):
            raise ValueError(f"a milestone vocabulary needs at least two distinct labels, got {self.labels}")
        if self.prompt.kind is not PromptKind.MCQ:
            raise ValueError("a milestone vocabulary is asked with an MCQ prompt")
        if self.prompt.options is None:  # the labels are the prompt's options (its text unchanged)
            object.__setattr__(self, "prompt", dataclasses.replace(self.prompt, options=self.labels))
        elif self.prompt.options != self.labels:
            raise ValueError(f"the MCQ prompt's options {self.prompt.options} are not the labels {self.labels}")


def mcq_prompt(scene: str, labels: tuple[str, ...]) -> Prompt:
    """The MCQ prompt asking ``scene``, then the choices ``labels`` and the answer format."""
    return Prompt(PromptKind.MCQ, f"{scene} Choose exactly one of: {', '.join(labels)}. Answer with the label only.",
                  options=tuple(labels))


@dataclass(frozen=True)
class NumberQuestions:
    """A task's float and box prompts, the float's range ``[low, high]`` and the frame's size in pixels.

    Example:
        >>> q = NumberQuestions(Prompt(PromptKind.FLOAT, "x?"), Prompt(PromptKind.BOX, "box?"), -1.0, 1.0, 64, 48)
        >>> q.box_prompt.text, q.potential(0.0), q.potential(5.0)
        ('box?', 0.5, 1.0)
    """

    float_prompt: Prompt
    box_prompt: Prompt
    low: float
    high: float
    width: int
    height: int

    def __post_init__(self) -> None:
        if self.float_prompt.kind is not PromptKind.FLOAT or self.box_prompt.kind is not PromptKind.BOX:
            raise ValueError("NumberQuestions takes a FLOAT prompt and a BOX prompt")
        if not self.low < self.high or self.width < 1 or self.height < 1:
            raise ValueError("NumberQuestions needs low < high and a frame of at least 1 x 1 pixels")

    def potential(self, value: float) -> float:
        """A float answer mapped linearly onto [0, 1] over ``[low, high]``, clipped."""
        return min(max((value - self.low) / (self.high - self.low), 0.0), 1.0)


class NumberTruth(Protocol):
    """The answer key of one frame: the reading ``x``, the agent's box and centre (pixels), the label."""

    @property
    def x(self) -> float: ...

    @property
    def box_px(self) -> tuple[float, float, float, float]: ...

    @property
    def centre_px(self) -> tuple[float, float]: ...

    @property
    def label(self) -> str: ...


class NumberRenderer(Protocol):
    """Draws a task's frame at any reading ``x``; closed when done."""

    def render(self, x: float, *, frame_id: str | None = None) -> Frame: ...

    def close(self) -> None: ...


#: One of Figure 1's frames: (panel, reading, caption), e.g. ("a", -0.50, "Absolute valley").
Panel = tuple[str, float, str]


@dataclass(frozen=True)
class NumberProbe(NumberQuestions):
    """``NumberQuestions`` with what Table 1 needs (``Task.numbers``): a ``renderer`` factory, the
    ``truth`` at a reading, Figure 1's ``panels`` (the first two Table 1's pair) and ``notes``."""

    renderer: Callable[[], NumberRenderer]
    truth: Callable[[float], NumberTruth]
    panels: tuple[Panel, ...]
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        super().__post_init__()
        names = [name for name, _, _ in self.panels]
        if len(names) < 2 or len(set(names)) != len(names):
            raise ValueError(f"a NumberProbe needs at least two panels with distinct names (Table 1's pair), "
                             f"got {names}")
        outside = [x for _, x, _ in self.panels if not (math.isfinite(x) and self.low <= x <= self.high)]
        if outside:
            raise ValueError(f"panel reading {outside[0]} lies outside the range [{self.low}, {self.high}]")

    @classmethod
    def of(cls, questions: NumberQuestions, *, renderer: Callable[[], NumberRenderer],
           truth: Callable[[float], NumberTruth], panels: tuple[Panel, ...],
           notes: tuple[str, ...] = ()) -> NumberProbe:
        """``questions`` with the probe's renderer, answer key, panels and notes."""
        asked = {f.name: getattr(questions, f.name) for f in dataclasses.fields(NumberQuestions)}
        return cls(**asked, renderer=renderer, truth=truth, panels=panels, notes=notes)
