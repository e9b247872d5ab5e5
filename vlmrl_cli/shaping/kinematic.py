"""Micro-kinematic dense reward (paper Section 3.3, Eq. 1)."""

from __future__ import annotations


def kinematic_reward(x: float, scale: float = 2.0, offset: float = 0.4) -> float:
    """``R_kin = max(0, scale (x + offset))``, paper Eq. 1 with its defaults 2.0 and 0.4.

    ``x`` is the car's position in track units (MountainCar's ``[-1.2, 0.6]``) read from the
    proprioceptive observation; the result is in reward units per step. It is zero left of
    ``-offset`` and grows linearly to the right (0 at the valley, 2.0 at the goal flag x=0.5).

    Example:
        >>> kinematic_reward(-0.5), kinematic_reward(0.1)
        (0.0, 1.0)
    """
    return max(0.0, scale * (float(x) + offset))
