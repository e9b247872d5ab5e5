"""What the hybrid reward needs to know of a task: its observation, its dense term, its camera.

A task plug-in (``vlmrl_cli.tasks``) fills a ``Scene``; the reward wrappers (``shaping.wrapper``)
read nothing else about the environment. MountainCar's (``tasks/mountain_car``) is the paper's: observation ``[x, v]``,
Eq. 1's kinematic term on ``x`` and a camera that images the position.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from vlmrl_cli.shaping.camera import FrameView

#: ``dense(obs, scale, offset)``: the dense "proprioceptive" term of one step, from the
#: observation only (``ShapingConfig.kin_scale`` and ``kin_offset``).
DenseTerm = Callable[[np.ndarray, float, float], float]

#: ``success(terminated, length)``: whether an episode that ended after ``length`` steps
#: succeeded, ``terminated`` telling an end the env itself made (its goal) from a time-limit cut.
#: A task's rule is ``Task.success``; the reward wrapper, the training callback and the detached
#: evaluation all take that one.
SuccessRule = Callable[[bool, int], bool]


def ended_by_env(terminated: bool, length: int) -> bool:
    """The success rule where no task gives one: the env itself ended the episode, at any length.

    Example:
        >>> ended_by_env(True, 5_000), ended_by_env(False, 10)
        (True, False)
    """
    return bool(terminated)


class SceneCamera(Protocol):
    """A run's camera: the one component that reads the simulator (``sim``, the unwrapped env)
    and turns its state into a ``FrameView`` (quantised, so that distinct frames are bounded)."""

    renders: int

    def look(self, sim: Any) -> FrameView: ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class Scene:
    """A task as the reward wrapper sees it.

    ``obs_shape``: the observation the dense term reads; ``dense``: that term; ``sim_type``: the
    unwrapped env class the camera images (checked when an arm uses the VLM).
    """

    name: str
    obs_shape: tuple[int, ...]
    dense: DenseTerm
    sim_type: type
