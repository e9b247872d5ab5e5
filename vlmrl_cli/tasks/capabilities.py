"""What a ``Task`` may have beyond what every task needs: small typed values, one per feature.

A task states the features it has by giving their values (``Task(hover=Hover(...))``); a feature
it does not give is off, and the code that uses it asks ``task.hover is None``. Every task needs a
``TaskCamera``; the rest are optional:

- ``Hover``: the hovering diagnostic (a coordinate read from an observation and where hovering
  starts), the reports' evidence of reward hacking;
- ``PaperTask``: the paper's own task, whose Table 2 the reports set beside the runs, whose
  baseline profile calibration aims at, and whose runs predate tasks (their hashes name none);
- ``StepCaption``: a played step as named fields and one caption line (``vlmrl evaluate``);
- ``TaskCamera.frames``: every frame the camera can show, so a replay transcript is checked
  before training.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from vlmrl_cli import paper
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.shaping.scene import SceneCamera


@dataclass(frozen=True)
class TaskCamera:
    """The run's camera and what the shaping needs to know of it.

    Attributes:
        make: the camera for a shaping config, quantised so that distinct frames (and a real VLM's
            queries per run) are bounded.
        feature_dim: the size of its frames' features (``shaping.features.feature_dim``).
        frames: every frame the camera can show under a shaping config, so that a replay
            transcript is checked to answer them all before training (None: not checked).
    """

    make: Callable[[ShapingConfig], SceneCamera]
    feature_dim: int
    frames: Callable[[ShapingConfig], list[Frame]] | None = None

    def __post_init__(self) -> None:
        if self.feature_dim < 1:
            raise ValueError(f"TaskCamera.feature_dim must be at least 1, not {self.feature_dim}")


@dataclass(frozen=True)
class Hover:
    """The hovering diagnostic: ``position`` reads the coordinate from an observation, and an
    episode hovers while it stays at or past ``start`` without finishing (``shaping.hacking``)."""

    position: Callable[[np.ndarray], float]
    start: float


@dataclass(frozen=True)
class PaperTask:
    """The paper's own task (MountainCar-v0 alone).

    Attributes:
        reported: the paper's reported figures (its Table 2 and Table 1), which reports set beside
            the runs and calibration's target profile is read from.
        budget: the paper's training budget (its Figure 2 runs to 300,000 steps), against which its
            baseline's steps are fractions when its profile is carried to another task.

    Its runs predate tasks, so their config hashes name no task."""

    reported: Path = paper.REPORTED
    budget: int = 300_000


class StepCaption(Protocol):
    """A played step's observation and action as named fields (``vlmrl evaluate``'s JSON) and one
    caption line of its GIF."""

    def __call__(self, obs: tuple[float, ...], action: Any, /) -> tuple[dict[str, Any], str]: ...
