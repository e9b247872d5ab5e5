"""The two scales of the hybrid reward (alpha, kin_scale), set per task by one stated rule
(issue 41): each term can pay at most a share of the goal's return. See docs/method.md."""

from __future__ import annotations

import math
from dataclasses import dataclass

#: The rule's shares of the goal's return (the potential term's, the dense term's whole-episode).
POTENTIAL_SHARE = 0.25
DENSE_SHARE = 0.25


@dataclass(frozen=True)
class TaskScales:
    """A task's alpha and kin_scale, ``rule`` (one line for reports) and ``kin_offset`` (None: Eq. 1's)."""

    alpha: float
    kin_scale: float
    rule: str
    kin_offset: float | None = None

    def knobs(self) -> dict[str, float]:
        """The ``[shaping]`` keys these scales set.

        Example:
            >>> TaskScales(12.5, 0.125, "r", kin_offset=1.0).knobs()
            {'alpha': 12.5, 'kin_scale': 0.125, 'kin_offset': 1.0}
        """
        own = {"alpha": self.alpha, "kin_scale": self.kin_scale}
        return own if self.kin_offset is None else own | {"kin_offset": self.kin_offset}

    def __post_init__(self) -> None:
        for name in ("alpha", "kin_scale"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"TaskScales.{name} must be finite and >= 0, got {value}")


def task_scales(goal_return: float, potential_span: float, dense_peak: float, horizon: int,
                potential_share: float = POTENTIAL_SHARE, dense_share: float = DENSE_SHARE,
                kin_offset: float | None = None) -> TaskScales:
    """alpha and kin_scale by the module's rule, to 3 significant figures."""
    for name, value in (("goal_return", goal_return), ("potential_span", potential_span),
                        ("dense_peak", dense_peak), ("horizon", horizon)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be finite and > 0, got {value}")
    alpha = float(f"{potential_share * goal_return / potential_span:.3g}")
    kin_scale = float(f"{dense_share * goal_return / (horizon * dense_peak):.3g}")
    rule = (f"to 3 significant figures, alpha x potential span = {potential_share:g} x goal return "
            f"({goal_return:g}); dense term's whole-episode maximum ({horizon} steps x {dense_peak:.4g} x "
            f"kin_scale) = {dense_share:g} x goal return")
    return TaskScales(alpha, kin_scale, rule, kin_offset)
