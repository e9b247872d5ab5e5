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
