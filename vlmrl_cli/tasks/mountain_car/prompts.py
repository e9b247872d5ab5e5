"""MountainCar's three prompts (paper Table 1): a float, a box and the zone MCQ, and its milestones."""

from __future__ import annotations

from vlmrl_cli.tasks.mountain_car.geometry import MAX_POSITION, MIN_POSITION, SCREEN_HEIGHT, SCREEN_WIDTH, ZONES
from vlmrl_cli.vlm.prompts import Milestones, NumberQuestions, Prompt, PromptKind

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
        options=tuple(z.value for z in ZONES),
    ),
}

#: The zones as an MCQ vocabulary (left to right).
ZONE_MILESTONES = Milestones(tuple(z.value for z in ZONES), PROMPTS[PromptKind.MCQ])

#: The float and box questions: a position on the track, a box in the 600 x 400 frame.
NUMBERS = NumberQuestions(PROMPTS[PromptKind.FLOAT], PROMPTS[PromptKind.BOX], MIN_POSITION, MAX_POSITION,
                          SCREEN_WIDTH, SCREEN_HEIGHT)
