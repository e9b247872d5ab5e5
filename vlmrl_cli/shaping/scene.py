"""What the hybrid reward knows of a task (``Scene``): its observation, its dense term, its
camera; the reward wrappers (``shaping.wrapper``) read nothing else about the environment."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from vlmrl_cli.shaping.camera import FrameView

#: ``dense(obs, scale, offset)``: the dense "proprioceptive" term of one step, from the
#: observation only (``ShapingConfig.kin_scale`` and ``kin_offset``).
DenseTerm = Callable[[np.ndarray, float, float], float]

#: ``success(terminated, length)``: whether an episode that ended after ``length`` steps succeeded
#: (``terminated``: the env ended it, not the time limit). A task's rule is ``Task.success``.
SuccessRule = Callable[[bool, int], bool]


def ended_by_env(terminated: bool, length: int) -> bool:
    """The success rule where no task gives one: the env itself ended the episode, at any length.

    Example:
        >>> ended_by_env(True, 5_000), ended_by_env(False, 10)
        (True, False)
    """
    return bool(terminated)


class SceneCamera(Protocol):
    """A run's camera: the one component that reads the simulator (``sim``, the unwrapped env)."""

    renders: int

    def look(self, sim: Any) -> FrameView: ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class Scene:
    """A task as the reward wrappers see it; ``sim_type``: the unwrapped env class the camera images."""

    name: str
    obs_shape: tuple[int, ...]
    dense: DenseTerm
    sim_type: type
