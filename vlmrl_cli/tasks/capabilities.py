"""What a ``Task`` may have beyond what every task needs: small typed values, one per feature. A
feature a task does not give is off (``task.hover is None``). See docs/tasks.md, "Add a task"."""

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
    """The run's camera: ``make`` builds it for a shaping config (quantised, so distinct frames are
    bounded), ``feature_dim`` is its frames' feature size, ``frames`` every frame it can show (replay
    transcripts are checked against them before training; None: not checked)."""

    make: Callable[[ShapingConfig], SceneCamera]
    feature_dim: int
    frames: Callable[[ShapingConfig], list[Frame]] | None = None

    def __post_init__(self) -> None:
        if self.feature_dim < 1:
            raise ValueError(f"TaskCamera.feature_dim must be at least 1, not {self.feature_dim}")


@dataclass(frozen=True)
class Hover:
    """The hovering diagnostic: an episode hovers while ``position(obs)`` stays at or past ``start``
    without finishing (``shaping.hacking``)."""

    position: Callable[[np.ndarray], float]
    start: float


@dataclass(frozen=True)
class PaperTask:
    """The paper's own task (MountainCar-v0 alone; its runs' config hashes name no task): ``reported``,
    its figures, which reports and calibration's target read; ``budget``, its training budget."""

    reported: Path = paper.REPORTED
    budget: int = 300_000


class StepCaption(Protocol):
    """A played step as named fields (``vlmrl evaluate``'s JSON) and one caption line of its GIF."""

    def __call__(self, obs: tuple[float, ...], action: Any, /) -> tuple[dict[str, Any], str]: ...
