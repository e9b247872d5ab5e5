"""One frozen configuration object for the hybrid reward (paper Sections 3.2-3.4)."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from annotated_types import Ge, Gt, Interval
from pydantic import BeforeValidator

from vlmrl_cli.frames.geometry import Zone

# Raw potential of each MCQ label (Phi_raw). The paper fixes only "0 -> 0.3 by reaching the
# left peak"; the rest is our choice, documented in README: the two slopes are a small first
# step, the left peak the paper's 0.3, the right hill before the flag 0.6, the goal 1.0.
DEFAULT_LABEL_POTENTIALS: tuple[tuple[str, float], ...] = (
    (Zone.LEFT_PEAK, 0.3),
    (Zone.LEFT_SLOPE, 0.1),
    (Zone.BOTTOM, 0.0),
    (Zone.RIGHT_SLOPE, 0.1),
    (Zone.NEAR_GOAL, 0.6),
    (Zone.GOAL, 1.0),
)


def _label_table(value: Any) -> Any:
    """TOML writes the label map as a table of the labels it changes (MountainCar's other zones
    keep their default); a full config gives ``[[label, potential], ...]``. Either way the result
    is a tuple of ``(label, potential)`` pairs; MountainCar's zones come back as ``Zone``. A table
    naming labels that are not zones is another task's whole map (the run's task checks it)."""
    if isinstance(value, dict):
        if set(value) <= set(Zone.__members__):
            value = list(({str(zone): p for zone, p in DEFAULT_LABEL_POTENTIALS} | value).items())
        else:
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
    return tuple((Zone(label) if label in Zone.__members__ else label, float(p)) for label, p in value)


_LABEL_NAME = re.compile(r"[A-Z][A-Z0-9_]*")


def label_problem(pairs: tuple[tuple[str, float], ...], labels: tuple[str, ...]) -> str | None:
    """Why a label map does not fit a task's ``labels`` (None when it does).

    Example:
        >>> label_problem(DEFAULT_LABEL_POTENTIALS, tuple(Zone)) is None
        True
        >>> label_problem(DEFAULT_LABEL_POTENTIALS[:-1], tuple(Zone))
        'no potential for GOAL; give a potential for every label'
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

    # MountainCar's zones by default; a run of another task replaces an unchanged default with
    # that task's map (training/config.py), and checks any map against the task's labels
    label_potentials: tuple[tuple[str, float], ...] = field(
        default=DEFAULT_LABEL_POTENTIALS,
        metadata={"rules": (BeforeValidator(_label_table),),
                  "help": "MCQ label -> raw potential (the task's labels)"}
    )
    alpha: float = field(default=5.0, metadata={"rules": (Ge(0),), "help": "PBRS scale (the paper gives none)"})
    gamma: float | None = field(default=None, metadata={"rules": (Interval(gt=0, le=1),),
                                                        "help": "PBRS discount; None = PPO's gamma"})
    query_every: int = field(default=10, metadata={"rules": (Ge(1),), "help": "ask the VLM at most every k env steps"})
    confirm: int = field(default=2, metadata={"rules": (Ge(1),), "help": "agreeing labels that confirm a milestone"})
    # Feature distance grows ~0.075 per pixel of car shift and saturates (~1.4) beyond ~40 px
    # (measured, see shaping/features.py): 0.3 keeps far prototypes from pulling Phi to the mean.
    bandwidth: float = field(default=0.3, metadata={"rules": (Gt(0),),
                                                    "help": "RBF kernel width, feature-distance units"})
    # 0 = reuse only an identical frame's label: a deterministic VLM answers it identically, so
    # the cache changes no label; > 0 also reuses the nearest prototype within this distance.
    reuse_radius: float = field(
        default=0.0, metadata={"rules": (Ge(0),),
                               "help": "also reuse a prototype's label within this feature distance (~0.075/px)"}
    )
    # the same rule as alpha: a scale weighs a term, and a negative one would pay for the opposite
    kin_scale: float = field(default=2.0, metadata={"rules": (Ge(0),), "help": "R_kin = max(0, scale (x + offset))"})
    kin_offset: float = field(default=0.4, metadata={"help": "see kin_scale (Eq. 1)"})
    # MountainCar's picture depends on x only; one pixel of car motion is 1.8 / 600 = 0.003 in x,
    # so at most 601 distinct frames exist and the VLM is asked at most 601 times per run.
    render_quantum: float = field(
        default=0.003, metadata={"rules": (Gt(0),), "help": "render positions on this grid (x units; 1 px = 0.003)"}
    )

    def potential_of(self, label: str) -> float:
        return dict(self.label_potentials)[label]
