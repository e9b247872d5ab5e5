"""One frozen configuration object for the hybrid reward (paper Sections 3.2-3.4)."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from annotated_types import Ge, Gt, Interval
from pydantic import BeforeValidator

from vlmrl_cli.core.fields import AtMost

#: The largest reward scale (alpha, kin_scale): a shaped term of scale 1e6 already dwarfs any task's
#: own reward, and one near 1e308 overflows to inf in PPO's float32 rollout buffer.
_SCALE_LIMIT = AtMost(1e6, "a larger scale makes the shaped term dwarf the task's own reward (the paper's dense term "
                           "has scale 2.0, the committed studies' largest alpha is 214), and near 1e308 it overflows "
                           "to inf in PPO's float32 rollout buffer")


def _label_table(value: Any) -> Any:
    """A label map as ``(label, potential)`` pairs, from a TOML table or ``[[label, potential], ...]``."""
    if isinstance(value, dict):
        value = list(value.items())
    if not isinstance(value, (list, tuple)) or not all(isinstance(p, (list, tuple)) and len(p) == 2 for p in value):
        raise ValueError("give a table of label = potential")
    bad = [label for label, _ in value if not isinstance(label, str) or not _LABEL_NAME.fullmatch(label)]
    if bad:
        raise ValueError(f"label '{bad[0]}' is not a label name (upper-case letters, digits and _)")
    if any(isinstance(p, bool) or not isinstance(p, (int, float)) for _, p in value):
        raise ValueError("every label's potential must be a number")
    if len({label for label, _ in value}) != len(value):
        raise ValueError("a label is given twice; give each label one potential")
    return tuple((str(label), float(p)) for label, p in value)


_LABEL_NAME = re.compile(r"[A-Z][A-Z0-9_]*")


def label_problem(pairs: tuple[tuple[str, float], ...], labels: tuple[str, ...]) -> str | None:
    """Why a label map does not fit a task's ``labels`` (None when it does).

    Example:
        >>> label_problem((("LOW", 0.0), ("HIGH", 1.0)), ("LOW", "HIGH")) is None
        True
        >>> label_problem((("LOW", 0.0),), ("LOW", "HIGH"))
        'no potential for HIGH; give a potential for every label'
    """
    given = [label for label, _ in pairs]
    unknown = [label for label in given if label not in labels]
    if unknown:
        return f"unknown label '{unknown[0]}'; known: {', '.join(labels)}"
    missing = [label for label in labels if label not in given]
    if missing:
        return f"no potential for {missing[0]}; give a potential for every label"
    return None


@dataclass(frozen=True)
class ShapingConfig:
    """Knobs of the semantic potential and the reward fusion; each field says its unit."""

    # empty: the task's own map (Task.label_potentials), filled in when a run's jobs are built
    label_potentials: tuple[tuple[str, float], ...] = field(
        default=(),
        metadata={"rules": (BeforeValidator(_label_table),),
                  "help": "MCQ label -> raw potential (empty: the task's own map)"}
    )
    alpha: float = field(default=5.0, metadata={"rules": (Ge(0), _SCALE_LIMIT), "help": "PBRS scale (the paper gives "
                                                                                       "none)"})
    gamma: float | None = field(default=None, metadata={"rules": (Interval(gt=0, le=1),),
                                                        "help": "PBRS discount; None = PPO's gamma"})
    query_every: int = field(default=10, metadata={"rules": (Ge(1),), "help": "ask the VLM at most every k env steps"})
    confirm: int = field(default=2, metadata={"rules": (Ge(1), AtMost(100, (
        "a milestone is confirmed by that many agreeing labels in a row, and an episode holds few queries "
        "(MountainCar's 200 steps, 20 at query_every 10): a larger value would never confirm one"))),
        "help": "agreeing labels that confirm a milestone"})
    # MountainCar's feature distance is ~0.075 per pixel of car shift, ~1.4 saturated (docs/method.md)
    bandwidth: float = field(default=0.3, metadata={"rules": (Gt(0),),
                                                    "help": "RBF kernel width, feature-distance units"})
    reuse_radius: float = field(
        default=0.0, metadata={"rules": (Ge(0),),
                               "help": "also reuse a prototype's label within this feature distance (~0.075/px)"}
    )
    # Eq. 1's knobs (the paper's 2.0 and 0.4); each task's dense term reads them (Task.scene.dense)
    kin_scale: float = field(default=2.0, metadata={
        "rules": (Ge(0), _SCALE_LIMIT), "help": "the dense term's scale (Eq. 1: max(0, scale (x + offset)))"})
    kin_offset: float = field(default=0.4, metadata={"help": "the dense term's offset (see kin_scale)"})
    # MountainCar's: one pixel of car motion, so at most 601 distinct frames per run
    render_quantum: float = field(
        default=0.003, metadata={"rules": (Gt(0),), "help": "render positions on this grid (the task's units)"}
    )

    def potential_of(self, label: str) -> float:
        return dict(self.label_potentials)[label]
