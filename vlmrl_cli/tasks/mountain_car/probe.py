"""Table 1 on MountainCar-v0 (``Task.numbers``): its float and box questions, renderer, answer key
and the paper's Figure 1 pair; the probe asks the task for these and imports nothing from here."""

from __future__ import annotations

from vlmrl_cli.tasks.mountain_car.geometry import GroundTruth
from vlmrl_cli.tasks.mountain_car.prompts import NUMBERS
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer
from vlmrl_cli.vlm.prompts import NumberProbe, Panel

#: The paper's Figure 1 pair, (panel, x, caption): always probed, whatever the sweep.
PAPER_FRAMES: tuple[Panel, ...] = (
    ("a", -0.50, "Absolute valley"),
    ("b", -0.69, "Lower left slope"),
)

PAPER_TRUE_CENTRES_NOTE = (
    "The paper prints the box truth as 'True Center: (120px,450px) -> (108px,446px)', which does not "
    "fit the 600x400 MountainCar frame; the centres shown here are computed from gymnasium's drawing "
    "geometry (column, row) in our 600x400 renders."
)
MCQ_TRUTH_NOTE = (
    "The paper's MCQ truth is 'Velocity v > 0 but x < 0'; a single frame shows no velocity, so the "
    "truth shown is the velocity-free zone of each position."
)

#: MountainCar's number probe: the position on the track [-1.2, 0.6], the box in the 600 x 400 frame.
NUMBER_PROBE = NumberProbe.of(NUMBERS, renderer=FrameRenderer, truth=GroundTruth.of, panels=PAPER_FRAMES,
                              notes=(PAPER_TRUE_CENTRES_NOTE, MCQ_TRUTH_NOTE))
