"""The three prompt kinds of the taxonomy probe (paper Table 1), defined in one place."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from vlmrl_cli.frames.geometry import ZONES


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


ZONE_CHOICES = ", ".join(z.value for z in ZONES)

PROMPTS: dict[PromptKind, Prompt] = {
    PromptKind.FLOAT: Prompt(
        PromptKind.FLOAT,
        "This image shows the MountainCar environment: a car on a one-dimensional track "
        "between x = -1.2 (left edge) and x = 0.6 (right edge). Estimate the car's horizontal "
        "position x. Answer with a single number only.",
    ),
    PromptKind.BOX: Prompt(
        PromptKind.BOX,
        "This image is 600 pixels wide and 400 pixels high. Give the bounding box of the car "
        "as [x_min, y_min, x_max, y_max] in pixel coordinates, origin at the top left. "
        "Answer with the box only.",
    ),
    PromptKind.MCQ: Prompt(
        PromptKind.MCQ,
        "This image shows a car on a valley-shaped track with a flag at the right. Where is "
        f"the car? Choose exactly one of: {ZONE_CHOICES}. Answer with the label only.",
    ),
}


@dataclass(frozen=True)
class Milestones:
    """A task's MCQ vocabulary: its ``labels`` in order (a flickering answer moves to a neighbour
    in this order) and the ``prompt`` that asks for one of them. MountainCar's is ``ZONE_MILESTONES``.

    Example:
        >>> ZONE_MILESTONES.labels[:2], ZONE_MILESTONES.prompt.kind
        (('LEFT_PEAK', 'LEFT_SLOPE'), <PromptKind.MCQ: 'mcq'>)
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


ZONE_MILESTONES = Milestones(tuple(z.value for z in ZONES), PROMPTS[PromptKind.MCQ])
