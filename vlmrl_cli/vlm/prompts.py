"""The three prompt kinds of the taxonomy probe (paper Table 1), and what a task asks with them:
its MCQ vocabulary (``Milestones``) and, where the picture has a number to read, its float and box
questions (``NumberQuestions``). MountainCar's prompts are ``tasks/mountain_car/prompts.py``."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum


class PromptKind(StrEnum):
    """Table 1's error taxonomy rows: I float regression, II box grounding, III semantic MCQ."""

    FLOAT = "float"
    BOX = "box"
    MCQ = "mcq"


@dataclass(frozen=True)
class Prompt:
    """A prompt kind and the exact text sent to the VLM with the frame."""

    kind: PromptKind
    text: str


@dataclass(frozen=True)
class Milestones:
    """A task's MCQ vocabulary: its ``labels`` in order (a flickering answer moves to a neighbour
    in this order) and the ``prompt`` that asks for one of them.

    Example:
        >>> m = Milestones(("LOW", "HIGH"), mcq_prompt("Is the arm low or high?", ("LOW", "HIGH")))
        >>> m.labels, m.prompt.kind
        (('LOW', 'HIGH'), <PromptKind.MCQ: 'mcq'>)
    """

    labels: tuple[str, ...]
    prompt: Prompt

    def __post_init__(self) -> None:
        if len(self.labels) < 2 or len(set(self.labels)) != len(self.labels):
            raise ValueError(f"a milestone vocabulary needs at least two distinct labels, got {self.labels}")
        if self.prompt.kind is not PromptKind.MCQ:
            raise ValueError("a milestone vocabulary is asked with an MCQ prompt")


def mcq_prompt(scene: str, labels: tuple[str, ...]) -> Prompt:
    """The MCQ prompt of a task: ``scene`` describes the picture and asks the question; the
    choices and the answer format follow, as in MountainCar's prompt."""
    return Prompt(PromptKind.MCQ, f"{scene} Choose exactly one of: {', '.join(labels)}. Answer with the label only.")


@dataclass(frozen=True)
class NumberQuestions:
    """A task's float and box questions (Table 1's rows I and II, and the ``vision-float`` arm):
    the two prompts, the range ``[low, high]`` a float answer must lie in (its potential maps
    it linearly onto [0, 1]), and the ``width`` x ``height`` of the frame a box must fit.

    Example:
        >>> q = NumberQuestions(Prompt(PromptKind.FLOAT, "x?"), Prompt(PromptKind.BOX, "box?"), -1.0, 1.0, 64, 48)
        >>> q.prompt(PromptKind.BOX).text, q.potential(0.0), q.potential(5.0)
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

    def prompt(self, kind: PromptKind) -> Prompt:
        """The float or the box prompt."""
        if kind is PromptKind.MCQ:
            raise ValueError("the MCQ prompt is the task's Milestones.prompt")
        return self.float_prompt if kind is PromptKind.FLOAT else self.box_prompt

    def potential(self, value: float) -> float:
        """A float answer mapped linearly onto [0, 1] over ``[low, high]``, clipped."""
        return min(max((value - self.low) / (self.high - self.low), 0.0), 1.0)
