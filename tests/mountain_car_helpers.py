"""MountainCar's arguments to the task-neutral parsers and simulated VLM, for the tests written
against them before the parsers took a range, a frame size and a vocabulary."""

from __future__ import annotations

from collections.abc import Sequence

from vlmrl_cli.tasks.mountain_car.prompts import NUMBERS, ZONE_MILESTONES
from vlmrl_cli.tasks.mountain_car.reader import WheelReader
from vlmrl_cli.vlm import parsers
from vlmrl_cli.vlm.config import SimKnobs
from vlmrl_cli.vlm.sim import MilestoneReader, SimulatedVLM

ZONE_LABELS = ZONE_MILESTONES.labels


def parse_float(text: str | None) -> parsers.FloatResult:
    return parsers.parse_float(text, NUMBERS.low, NUMBERS.high)


def parse_box(text: str | None) -> parsers.BoxResult:
    return parsers.parse_box(text, NUMBERS.width, NUMBERS.height)


def parse_mcq(text: str | None, labels: Sequence[str] | None = None) -> parsers.MCQResult:
    return parsers.parse_mcq(text, ZONE_LABELS if labels is None else labels)


def sim_vlm(knobs: SimKnobs | None = None, stream: int = 0, reader: MilestoneReader | None = None) -> SimulatedVLM:
    """The simulated VLM reading ``reader``'s frames (MountainCar-v0's wheel reader by default)."""
    return SimulatedVLM(WheelReader() if reader is None else reader, knobs, stream=stream)
