"""Hysteresis lock on confirmed milestones (paper Section 3.2), as a pure step function."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class LockState:
    """The lock of one episode (the default: its start): ``level`` the locked potential,
    ``candidate`` the latest label's raw potential, ``count`` how many labels in a row agreed on it."""

    level: float = 0.0
    candidate: float | None = None
    count: int = 0


def lock_step(state: LockState, label_potential: float, confirm: int) -> LockState:
    """The lock after one more label's raw potential: a potential that ``confirm`` labels in a row
    agree on (equal potentials) and above ``level`` becomes the level, which never drops."""
    if confirm < 1:
        raise ValueError(f"confirm must be >= 1, got {confirm}")
    p = float(label_potential)
    count = state.count + 1 if state.candidate == p else 1
    level = max(state.level, p) if count >= confirm else state.level
    return LockState(level=level, candidate=p, count=count)
