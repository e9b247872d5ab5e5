"""Scoring a VLM on frames (paper Section 2): which frames, asking, parsing, and the statistics.

Everything that depends on the environment comes from the task: ``Task.numbers`` (a
``NumberProbe``: the float and box questions, the range of a float answer and the frame a box must
fit, a renderer at any reading, the answer key there, Figure 1's frames) and ``Task.milestones``
and ``Task.label_potentials`` for the MCQ. Each probed frame keeps the potentials its answers and
its truth give, so the statistics need no task.

Shared by the taxonomy probe (``taxonomy.py``), Table 1 (``table1.py``) and Figure 1
(``figure1.py``), which import this module and never each other in a circle.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from vlmrl_cli.core.errors import BadInput, MissingAnswer
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.probe import metrics
from vlmrl_cli.probe.states import DEFAULT_STATES
from vlmrl_cli.tasks.base import Task
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
from vlmrl_cli.vlm.prompts import NumberProbe, NumberQuestions, NumberRenderer, NumberTruth, Prompt, PromptKind


@dataclass(frozen=True)
class FrameProbe:
    """One probed frame: its ground truth, the three raw answers (None: no answer), their parses
    and the potentials ``phi[kind] = (VLM's, truth's)`` they give (NaN: unparsed answer).

    ``panel`` is "a"/"b" for the paper's Figure 1 frames, else None; ``frame`` is kept only
    for those (the figure draws them).
    """

    frame_id: str
    truth: NumberTruth
    answers: Mapping[PromptKind, str | None]
    float_result: FloatResult
    box_result: BoxResult
    mcq_result: MCQResult
    phi: Mapping[PromptKind, tuple[float, float]]
    panel: str | None = None
    caption: str | None = None
    frame: Frame | None = None


def number_probe(task: Task) -> NumberProbe:
    """The task's number probe (``Task.numbers``); ``BadInput`` for a task that asks for no number."""
    if task.numbers is None:
        raise BadInput(f"task {task.name} asks for no number (its Task has no numbers), so Table 1's float and "
                       f"box probe is not defined for it; its taxonomy is the milestone MCQ (vlmrl taxonomy "
                       f"--task {task.name}).")
    return task.numbers


def table1_prompts(task: Task) -> dict[PromptKind, Prompt]:
    """The three prompts Table 1 asks of each frame, in its rows' order: the task's float and
    box questions and its milestone MCQ."""
    numbers = number_probe(task)
    return {PromptKind.FLOAT: numbers.float_prompt, PromptKind.BOX: numbers.box_prompt,
            PromptKind.MCQ: task.milestones.prompt}


# --- which frames ----------------------------------------------------------------------------

def frame_id_of(x: float) -> str:
    """A readable id for reading ``x``: two decimals unless more are needed (``x=-0.50``).

    Example:
        >>> frame_id_of(-0.5), frame_id_of(-1.125)
        ('x=-0.50', 'x=-1.125')
    """
    for decimals in range(2, 10):
        if abs(round(x, decimals) - x) < 1e-9:
            return f"x={x:.{decimals}f}"
    return f"x={x!r}"


_FRAME_ID = re.compile(r"^\s*x\s*=\s*([-+]?(?:\d+(?:\.\d*)?|\.\d+))\s*$")


def x_of_frame_id(frame_id: str, numbers: NumberQuestions) -> float | None:
    """The reading in a frame id written by ``frame_id_of``, or None if it holds none in the
    range ``[numbers.low, numbers.high]``."""
    match = _FRAME_ID.match(frame_id)
    if match is None:
        return None
    x = float(match.group(1))
    return x if numbers.low <= x <= numbers.high else None


def sweep_positions(states: int, numbers: NumberQuestions) -> list[float]:
    """``states`` readings evenly spaced over ``[numbers.low, numbers.high]``, ends included
    (the task's units; MountainCar: positions on the track)."""
    return [float(x) for x in np.linspace(numbers.low, numbers.high, states)]


@dataclass(frozen=True)
class _Planned:
    x: float
    frame_id: str
    panel: str | None = None
    caption: str | None = None


def plan_frames(states: int | None, backend: Backend, numbers: NumberProbe) -> tuple[list[_Planned], bool]:
    """The frames to probe, sorted by reading, and whether they form a sweep.

    A sweep is ``states`` evenly spaced readings plus the task's panels (``numbers.panels``,
    the paper's two frames on MountainCar). Without ``states`` a replay backend probes its
    transcript's frames (plus the panels) and there is no sweep; any other backend sweeps
    ``DEFAULT_STATES`` readings.
    """
    planned: dict[float, _Planned] = {}
    for panel, x, caption in numbers.panels:
        planned[round(x, 9)] = _Planned(x, frame_id_of(x), panel, caption)
    recorded_ids = getattr(backend, "frame_ids", None)
    if states is None and callable(recorded_ids):
        positions = [x for x in (x_of_frame_id(f, numbers) for f in recorded_ids()) if x is not None]
        is_sweep = False
    else:
        positions = sweep_positions(states or DEFAULT_STATES, numbers)
        is_sweep = True
    for x in positions:
        planned.setdefault(round(x, 9), _Planned(x, frame_id_of(x)))
    return sorted(planned.values(), key=lambda p: p.x), is_sweep


# --- probing ---------------------------------------------------------------------------------

def _ask(client: VLMClient, prompt: Prompt, frame: Frame) -> str | None:
    try:
        return client.ask(prompt, frame).text
    except MissingAnswer:
        return None  # replay has no record: scored as NO_ANSWER, never a crash


def probe_frame(client: VLMClient, task: Task, renderer: NumberRenderer, planned: _Planned) -> FrameProbe:
    """Render one frame of ``task`` (``renderer``: its ``NumberProbe``'s), ask all three
    prompts, parse the answers and turn them and the truth into potentials: MCQ label -> the
    task's raw potential; float: the reading normalised over the task's range; box: the centre
    column normalised by the frame width. Unparsed answers are NaN."""
    numbers = number_probe(task)
    frame = renderer.render(planned.x, frame_id=planned.frame_id)
    answers = {kind: _ask(client, prompt, frame) for kind, prompt in table1_prompts(task).items()}
    truth = numbers.truth(planned.x)
    float_result = parse_float(answers[PromptKind.FLOAT], numbers.low, numbers.high)
    box_result = parse_box(answers[PromptKind.BOX], numbers.width, numbers.height)
    mcq_result = parse_mcq(answers[PromptKind.MCQ], task.milestones.labels)
    label_map = dict(task.label_potentials)
    phi = {
        PromptKind.FLOAT: (
            metrics.position_potential(float_result.value if float_result.ok else None, numbers.low, numbers.high),
            metrics.position_potential(truth.x, numbers.low, numbers.high)),
        PromptKind.BOX: (metrics.box_potential(box_result.box if box_result.ok else None, numbers.width),
                         metrics.box_potential(truth.box_px, numbers.width)),
        PromptKind.MCQ: (metrics.label_potential(mcq_result.label if mcq_result.ok else None, label_map),
                         metrics.label_potential(truth.label, label_map)),
    }
    return FrameProbe(
        frame_id=planned.frame_id,
        truth=truth,
        answers=answers,
        float_result=float_result,
        box_result=box_result,
        mcq_result=mcq_result,
        phi=phi,
        panel=planned.panel,
        caption=planned.caption,
        frame=frame if planned.panel is not None else None,
    )


# --- statistics ------------------------------------------------------------------------------

def phi_series(probes: list[FrameProbe] | tuple[FrameProbe, ...], kind: PromptKind) -> tuple[np.ndarray, np.ndarray]:
    """(VLM potential, true potential) of each probe for one prompt kind, shapes (n,), (n,): the
    ``phi`` each probe was scored with (``probe_frame``); unparsed answers are NaN."""
    pairs = [p.phi[kind] for p in probes]
    return (np.asarray([v for v, _ in pairs], dtype=float), np.asarray([t for _, t in pairs], dtype=float))


def sweep_statistics(probes: list[FrameProbe] | tuple[FrameProbe, ...]) -> dict[str, float]:
    """All sweep statistics as flat ``kind.metric`` -> value (NaN: not computable), over the
    probes sorted by reading. Units: ``float.mae_x`` the task's (MountainCar: x units),
    ``box.centre_error_px`` pixels, fractions in [0, 1]."""
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
                                               [p.truth.label for p in ordered])

    for kind in PromptKind:
        vlm, true = phi_series(ordered, kind)
        for name, value in metrics.delta_phi_stats(vlm, true).as_dict().items():
            if name != "n_states":
                out[f"{kind.value}.dphi.{name}"] = value
    return out


def empty_sweep_statistics() -> dict[str, float]:
    """The sweep statistics' keys, all NaN (n/a): for runs that probe no sweep."""
    return {k: math.nan for k in sweep_statistics([])}
