"""Scoring a VLM on frames (paper Section 2): which frames, asking, parsing, and the statistics.

Shared by the taxonomy probe (``taxonomy.py``), Table 1 (``table1.py``) and Figure 1
(``figure1.py``), which import this module and never each other in a circle.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from vlmrl_cli.core.errors import MissingAnswer
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.probe import metrics
from vlmrl_cli.tasks.mountain_car.geometry import MAX_POSITION, MIN_POSITION, SCREEN_WIDTH, GroundTruth
from vlmrl_cli.tasks.mountain_car.prompts import NUMBERS, PROMPTS, ZONE_MILESTONES
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer
from vlmrl_cli.tasks.mountain_car.task import ZONE_POTENTIALS
from vlmrl_cli.vlm.base import Backend
from vlmrl_cli.vlm.client import VLMClient
from vlmrl_cli.vlm.parsers import (
    BoxResult,
    FloatResult,
    MCQResult,
    ParseStatus,
    parse_box,
    parse_float,
    parse_mcq,
)
from vlmrl_cli.vlm.prompts import PromptKind

# 101 sweep positions (+ the paper's two frames): a rank correlation of 0 over 103 frames has a 95%
# interval of about +-0.2 (25 positions gave +-0.4, too wide to tell "no rank signal" from a weak
# one), and no position falls within 2 px of a zone edge, where a reader off by a fraction of a
# pixel flips the label (25 positions put three frames exactly on edges).
DEFAULT_STATES = 101
#: Table 1's potentials of each answer kind, MountainCar's: the track of a float answer, the frame
#: width of a box's centre, the label map of an MCQ answer.
TRACK = (MIN_POSITION, MAX_POSITION)
LABEL_MAP = dict(ZONE_POTENTIALS)
# The paper's Figure 1 pair: (panel, x, caption). Always probed, whatever the sweep.
PAPER_FRAMES: tuple[tuple[str, float, str], ...] = (
    ("a", -0.50, "Absolute valley"),
    ("b", -0.69, "Lower left slope"),
)

@dataclass(frozen=True)
class FrameProbe:
    """One probed frame: its ground truth, the three raw answers (None: no answer) and parses.

    ``panel`` is "a"/"b" for the paper's Figure 1 frames, else None; ``frame`` is kept only
    for those (the figure draws them).
    """

    frame_id: str
    truth: GroundTruth
    answers: Mapping[PromptKind, str | None]
    float_result: FloatResult
    box_result: BoxResult
    mcq_result: MCQResult
    panel: str | None = None
    caption: str | None = None
    frame: Frame | None = None


# --- which frames ----------------------------------------------------------------------------

def frame_id_of(x: float) -> str:
    """A readable id for position ``x``: two decimals unless more are needed (``x=-0.50``).

    Example:
        >>> frame_id_of(-0.5), frame_id_of(-1.125)
        ('x=-0.50', 'x=-1.125')
    """
    for decimals in range(2, 10):
        if abs(round(x, decimals) - x) < 1e-9:
            return f"x={x:.{decimals}f}"
    return f"x={x!r}"


_FRAME_ID = re.compile(r"^\s*x\s*=\s*([-+]?(?:\d+(?:\.\d*)?|\.\d+))\s*$")


def x_of_frame_id(frame_id: str) -> float | None:
    """The position in a frame id written by ``frame_id_of``, or None if it holds none."""
    match = _FRAME_ID.match(frame_id)
    if match is None:
        return None
    x = float(match.group(1))
    return x if MIN_POSITION <= x <= MAX_POSITION else None


def sweep_positions(states: int) -> list[float]:
    """``states`` positions evenly spaced over the track, ends included (x units)."""
    return [float(x) for x in np.linspace(MIN_POSITION, MAX_POSITION, states)]


@dataclass(frozen=True)
class _Planned:
    x: float
    frame_id: str
    panel: str | None = None
    caption: str | None = None


def plan_frames(states: int | None, backend: Backend) -> tuple[list[_Planned], bool]:
    """The frames to probe, sorted by x, and whether they form a sweep.

    A sweep is ``states`` evenly spaced positions plus the paper's two frames. Without
    ``states`` a replay backend probes its transcript's frames (plus the paper's two) and
    there is no sweep; any other backend sweeps ``DEFAULT_STATES`` positions.
    """
    planned: dict[float, _Planned] = {}
    for panel, x, caption in PAPER_FRAMES:
        planned[round(x, 9)] = _Planned(x, frame_id_of(x), panel, caption)
    recorded_ids = getattr(backend, "frame_ids", None)
    if states is None and callable(recorded_ids):
        positions = [x for x in (x_of_frame_id(f) for f in recorded_ids()) if x is not None]
        is_sweep = False
    else:
        positions = sweep_positions(states or DEFAULT_STATES)
        is_sweep = True
    for x in positions:
        planned.setdefault(round(x, 9), _Planned(x, frame_id_of(x)))
    return sorted(planned.values(), key=lambda p: p.x), is_sweep


# --- probing ---------------------------------------------------------------------------------

def _ask(client: VLMClient, kind: PromptKind, frame: Frame) -> str | None:
    try:
        return client.ask(PROMPTS[kind], frame).text
    except MissingAnswer:
        return None  # replay has no record: scored as NO_ANSWER, never a crash


def probe_frame(client: VLMClient, renderer: FrameRenderer, planned: _Planned) -> FrameProbe:
    """Render one frame, ask all three prompts, parse the answers."""
    frame = renderer.render(planned.x, frame_id=planned.frame_id)
    answers = {kind: _ask(client, kind, frame) for kind in PromptKind}
    return FrameProbe(
        frame_id=planned.frame_id,
        truth=GroundTruth.of(planned.x),
        answers=answers,
        float_result=parse_float(answers[PromptKind.FLOAT], NUMBERS.low, NUMBERS.high),
        box_result=parse_box(answers[PromptKind.BOX], NUMBERS.width, NUMBERS.height),
        mcq_result=parse_mcq(answers[PromptKind.MCQ], ZONE_MILESTONES.labels),
        panel=planned.panel,
        caption=planned.caption,
        frame=frame if planned.panel is not None else None,
    )


# --- statistics ------------------------------------------------------------------------------

def phi_series(probes: list[FrameProbe] | tuple[FrameProbe, ...], kind: PromptKind) -> tuple[np.ndarray, np.ndarray]:
    """(VLM potential, true potential) of each probe for one prompt kind, shapes (n,), (n,).

    MCQ: label -> raw potential; float: x normalised over the track; box: centre column
    normalised by the frame width. The truth applies the same mapping to the ground truth;
    unparsed answers are NaN.
    """
    vlm, true = [], []
    for p in probes:
        if kind is PromptKind.FLOAT:
            vlm.append(metrics.position_potential(p.float_result.value if p.float_result.ok else None, *TRACK))
            true.append(metrics.position_potential(p.truth.x, *TRACK))
        elif kind is PromptKind.BOX:
            vlm.append(metrics.box_potential(p.box_result.box if p.box_result.ok else None, SCREEN_WIDTH))
            true.append(metrics.box_potential(p.truth.box_px, SCREEN_WIDTH))
        else:
            vlm.append(metrics.label_potential(p.mcq_result.label if p.mcq_result.ok else None, LABEL_MAP))
            true.append(metrics.label_potential(p.truth.zone, LABEL_MAP))
    return np.asarray(vlm, dtype=float), np.asarray(true, dtype=float)


def sweep_statistics(probes: list[FrameProbe] | tuple[FrameProbe, ...]) -> dict[str, float]:
    """All sweep statistics as flat ``kind.metric`` -> value (NaN: not computable), over the
    probes sorted by x. Units: ``float.mae_x`` x units, ``box.centre_error_px`` pixels,
    fractions in [0, 1]."""
    ordered = sorted(probes, key=lambda p: p.truth.x)
    out: dict[str, float] = {"states": float(len(ordered))}

    def nanmean(values: list[float]) -> float:
        return float(np.mean(values)) if values else math.nan

    floats = [p.float_result for p in ordered]
    x_pred = [f.value if f.ok and f.value is not None else math.nan for f in floats]
    x_true = [p.truth.x for p in ordered]
    out["float.ok_fraction"] = nanmean([float(f.ok) for f in floats])
    out["float.format_failure_rate"] = metrics.format_failure_rate(f.status for f in floats)
    out["float.out_of_range_rate"] = nanmean([float(f.status is ParseStatus.OUT_OF_RANGE) for f in floats])
    out["float.mae_x"] = float(np.nanmean(metrics.absolute_error(x_pred, x_true))) if any(
        math.isfinite(v) for v in x_pred) else math.nan
    out["float.spearman"] = metrics.spearman(x_pred, x_true)
    out["float.spearman_low"], out["float.spearman_high"] = metrics.spearman_ci(
        out["float.spearman"], len(metrics.finite_pairs(x_pred, x_true)[0]))

    boxes = [p.box_result for p in ordered]
    ious = [metrics.iou(b.box, p.truth.box_px) for b, p in zip(boxes, ordered, strict=True) if b.ok and b.box]
    centre = [metrics.centre_error_px(b.box, p.truth.box_px) for b, p in zip(boxes, ordered, strict=True)
              if b.ok and b.box]
    out["box.ok_fraction"] = nanmean([float(b.ok) for b in boxes])
    out["box.format_failure_rate"] = metrics.format_failure_rate(b.status for b in boxes)
    out["box.out_of_range_rate"] = nanmean([float(b.status is ParseStatus.OUT_OF_RANGE) for b in boxes])
    out["box.mean_iou"] = nanmean(ious)
    # failures count as IoU 0: what a shaping signal built on the boxes would actually get
    out["box.mean_iou_all"] = sum(ious) / len(boxes) if boxes else math.nan
    out["box.centre_error_px"] = nanmean(centre)

    mcqs = [p.mcq_result for p in ordered]
    out["mcq.ok_fraction"] = nanmean([float(m.ok) for m in mcqs])
    out["mcq.format_failure_rate"] = metrics.format_failure_rate(m.status for m in mcqs)
    out["mcq.accuracy"] = metrics.mcq_accuracy([m.label if m.ok else None for m in mcqs],
                                               [p.truth.zone for p in ordered])

    for kind in PromptKind:
        vlm, true = phi_series(ordered, kind)
        for name, value in metrics.delta_phi_stats(vlm, true).as_dict().items():
            if name != "n_states":
                out[f"{kind.value}.dphi.{name}"] = value
    return out


def empty_sweep_statistics() -> dict[str, float]:
    """The sweep statistics' keys, all NaN (n/a): for runs that probe no sweep."""
    return {k: math.nan for k in sweep_statistics([])}
