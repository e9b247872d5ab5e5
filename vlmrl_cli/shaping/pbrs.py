"""The potential-based shaping term of the reward fusion (paper Section 3.4, Eq. 2)."""

from __future__ import annotations


def pbrs_term(phi: float, phi_next: float, gamma: float, alpha: float, terminated: bool) -> float:
    """``alpha (gamma Phi(s') - Phi(s))`` (Ng, Harada & Russell 1999), in reward units.

    ``phi_next`` counts as 0 when the episode ``terminated`` (an absorbing state), and is kept on
    a truncation (the learner bootstraps from it). Along any episode the discounted sum telescopes
    to ``alpha (gamma^T Phi_T - Phi_0)``, whatever the potentials (docs/method.md)."""
    target = 0.0 if terminated else float(phi_next)
    return float(alpha) * (float(gamma) * target - float(phi))
