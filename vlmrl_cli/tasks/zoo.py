"""rl-baselines3-zoo's published PPO scores, by gymnasium id: the top of the ``--normalise zoo``
range of ``vlmrl compare``.

Copied from the zoo's ``benchmark.md`` (DLR-RM/rl-baselines3-zoo at commit 22e3ff2; the first three
rows are the same at 02a1a90), its ``ppo`` rows: mean and std of the episode return of the trained
agent, and its training budget. Each task's ``zoo_reference`` cites the same numbers in words;
a test keeps the two in step.

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
