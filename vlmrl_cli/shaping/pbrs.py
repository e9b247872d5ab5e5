"""The potential-based shaping term of the reward fusion (paper Section 3.4, Eq. 2)."""

from __future__ import annotations


def pbrs_term(phi: float, phi_next: float, gamma: float, alpha: float, terminated: bool) -> float:
    """``alpha (gamma Phi(s') - Phi(s))`` (Ng, Harada & Russell 1999), in reward units.

    ``phi`` and ``phi_next`` are the (dimensionless) potentials of the current and the next
    state, ``gamma`` the discount in ``(0, 1]``, ``alpha`` the shaping scale. When the episode
    ``terminated`` (the goal, an absorbing state) the next potential counts as 0, so shaping
    cannot change which policy is optimal. On a truncation (time limit) ``phi_next`` is kept:
    the learner bootstraps the value of the last observation, so that state is not absorbing.

    Along any episode the discounted sum of these terms telescopes to
    ``alpha (gamma^T Phi_T - Phi_0)`` (``Phi_T = 0`` when terminated), whatever the potentials
    are: a loop back to the same potential earns ``alpha (gamma^T - 1) Phi_0 <= 0``.

    Example:
        >>> pbrs_term(0.0, 0.5, gamma=1.0, alpha=4.0, terminated=False)
        2.0
        >>> pbrs_term(0.6, 1.0, gamma=1.0, alpha=5.0, terminated=True)
        -3.0
    """
    target = 0.0 if terminated else float(phi_next)
    return float(alpha) * (float(gamma) * target - float(phi))
