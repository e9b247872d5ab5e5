"""rl-baselines3-zoo's published PPO scores by gymnasium id (its ``benchmark.md`` at 22e3ff2, ``ppo``
rows): the top of ``vlmrl compare --normalise zoo``'s range. A test keeps each task's
``zoo_reference`` in step.

Example:
    >>> ZOO_PPO["MountainCar-v0"].mean
    -110.423
"""

from __future__ import annotations

from dataclasses import dataclass

SOURCE = "rl-baselines3-zoo benchmark.md (DLR-RM/rl-baselines3-zoo at 22e3ff2), PPO rows"


@dataclass(frozen=True)
class ZooScore:
    """The zoo's PPO result on one env: ``mean`` +/- ``std`` episode return after ``budget`` steps."""

    mean: float
    std: float
    budget: str


ZOO_PPO: dict[str, ZooScore] = {
    "MountainCar-v0": ZooScore(-110.423, 19.473, "1M"),
    "MountainCarContinuous-v0": ZooScore(88.343, 2.572, "20k"),
    "Acrobot-v1": ZooScore(-73.506, 18.201, "1M"),
    "MiniGrid-DoorKey-5x5-v0": ZooScore(0.964, 0.006, "100k"),
}
