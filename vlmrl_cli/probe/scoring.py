"""Scoring a VLM on a task's frames (paper Section 2): which frames, asking, parsing, statistics."""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

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
    """One probed frame: truth, answers, parses, ``phi[kind] = (VLM's, truth's)``; ``frame``: panels only."""

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

    def result(self, kind: PromptKind) -> FloatResult | BoxResult | MCQResult:
        """The parse of the answer to prompt ``kind``."""
        results: dict[PromptKind, FloatResult | BoxResult] = {PromptKind.FLOAT: self.float_result,
                                                               PromptKind.BOX: self.box_result}
        return results.get(kind, self.mcq_result)


def number_probe(task: Task) -> NumberProbe:
    """The task's number probe (``Task.numbers``); ``BadInput`` for a task that asks for no number."""
    if task.numbers is None:
        raise BadInput(f"task {task.name} asks for no number (its Task has no numbers), so Table 1's float and "
                       f"box probe is not defined for it; its taxonomy is the milestone MCQ (vlmrl taxonomy "
                       f"--task {task.name}).")
    return task.numbers


def table1_prompts(task: Task) -> dict[PromptKind, Prompt]:
    """The three prompts Table 1 asks of each frame, in its rows' order."""
    numbers = number_probe(task)
    return {PromptKind.FLOAT: numbers.float_prompt, PromptKind.BOX: numbers.box_prompt,
            PromptKind.MCQ: task.milestones.prompt}


def frame_id_of(x: float) -> str:
    """A readable id for reading ``x``: two decimals unless more are needed (``x=-0.50``)."""
    for decimals in range(2, 10):
        if abs(round(x, decimals) - x) < 1e-9:
            return f"x={x:.{decimals}f}"
    return f"x={x!r}"


_FRAME_ID = re.compile(r"^\s*x\s*=\s*([-+]?(?:\d+(?:\.\d*)?|\.\d+))\s*$")


def x_of_frame_id(frame_id: str, numbers: NumberQuestions) -> float | None:
    """The reading in a ``frame_id_of`` id, or None if it holds none in ``numbers``' range."""
    match = _FRAME_ID.match(frame_id)
    if match is None:
        return None
    x = float(match.group(1))
    return x if numbers.low <= x <= numbers.high else None


def sweep_positions(states: int, numbers: NumberQuestions) -> list[float]:
    """``states`` readings evenly spaced over ``numbers``' range, ends included."""
    return [float(x) for x in np.linspace(numbers.low, numbers.high, states)]


@dataclass(frozen=True)
class _Planned:
    x: float
    frame_id: str
    panel: str | None = None
    caption: str | None = None


def plan_frames(states: int | None, backend: Backend, numbers: NumberProbe) -> tuple[list[_Planned], bool]:
    """The panels and a sweep of ``states`` (None: replay's own frames), by reading; and if a sweep."""
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


def _ask(client: VLMClient, prompt: Prompt, frame: Frame) -> str | None:
    try:
        return client.ask(prompt, frame).text
    except MissingAnswer:
        return None  # replay has no record: scored as NO_ANSWER, never a crash


def _phi(answer: Any, potential: Callable[[Any], float]) -> float:
    return math.nan if answer is None else float(potential(answer))


def probe_frame(client: VLMClient, task: Task, renderer: NumberRenderer, planned: _Planned) -> FrameProbe:
    """Render, ask the three prompts, parse, and map answers and truth to potentials (NaN: unparsed)."""
    numbers = number_probe(task)
    frame = renderer.render(planned.x, frame_id=planned.frame_id)
    answers = {kind: _ask(client, prompt, frame) for kind, prompt in table1_prompts(task).items()}
    truth = numbers.truth(planned.x)
    float_result = parse_float(answers[PromptKind.FLOAT], numbers.low, numbers.high)
    box_result = parse_box(answers[PromptKind.BOX], numbers.width, numbers.height)
    mcq_result = parse_mcq(answers[PromptKind.MCQ], task.milestones.labels)
    label_map = dict(task.label_potentials)

    def box_phi(box: metrics.Box) -> float:
        return metrics.box_centre(box)[0] / numbers.width

    phi = {
        PromptKind.FLOAT: (_phi(float_result.value if float_result.ok else None, numbers.potential),
                           numbers.potential(truth.x)),
        PromptKind.BOX: (_phi(box_result.box if box_result.ok else None, box_phi), box_phi(truth.box_px)),
        PromptKind.MCQ: (_phi(mcq_result.label if mcq_result.ok else None, label_map.__getitem__),
                         float(label_map[truth.label])),
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


def phi_series(probes: list[FrameProbe] | tuple[FrameProbe, ...], kind: PromptKind) -> tuple[np.ndarray, np.ndarray]:
    """(VLM potentials, true potentials) of ``probes`` for one prompt kind, shapes (n,), (n,)."""
    pairs = [p.phi[kind] for p in probes]
    return (np.asarray([v for v, _ in pairs], dtype=float), np.asarray([t for _, t in pairs], dtype=float))


def sweep_statistics(probes: list[FrameProbe] | tuple[FrameProbe, ...]) -> dict[str, float]:
    """The sweep statistics, ``kind.metric`` -> value (NaN: not computable), over probes sorted by reading."""
    ordered = sorted(probes, key=lambda p: p.truth.x)
    out: dict[str, float] = {"states": float(len(ordered))}

    def nanmean(values: list[float]) -> float:
        return float(np.mean(values)) if values else math.nan

    for kind in PromptKind:
        results = [p.result(kind) for p in ordered]
        out[f"{kind}.ok_fraction"] = nanmean([float(r.ok) for r in results])
        out[f"{kind}.format_failure_rate"] = metrics.format_failure_rate(r.status for r in results)
        if kind is not PromptKind.MCQ:
            out[f"{kind}.out_of_range_rate"] = nanmean([float(r.status is ParseStatus.OUT_OF_RANGE) for r in results])
        vlm, true = phi_series(ordered, kind)
        for name, value in metrics.delta_phi_stats(vlm, true).items():
            if name != "n_states":
                out[f"{kind}.dphi.{name}"] = value

    floats = [p.float_result for p in ordered]
    x_pred = [f.value if f.ok and f.value is not None else math.nan for f in floats]
    x_true = [p.truth.x for p in ordered]
    out["float.mae_x"] = float(np.nanmean(np.abs(np.asarray(x_pred) - np.asarray(x_true)))) if any(
        math.isfinite(v) for v in x_pred) else math.nan
    out["float.spearman"] = metrics.spearman(x_pred, x_true)
    out["float.spearman_low"], out["float.spearman_high"] = metrics.spearman_ci(
        out["float.spearman"], len(metrics.finite_pairs(x_pred, x_true)[0]))

    boxes = [p.box_result for p in ordered]
    ious = [metrics.iou(b.box, p.truth.box_px) for b, p in zip(boxes, ordered, strict=True) if b.ok and b.box]
    centre = [metrics.centre_error_px(b.box, p.truth.box_px) for b, p in zip(boxes, ordered, strict=True)
              if b.ok and b.box]
    out["box.mean_iou"] = nanmean(ious)
    # failures count as IoU 0: what a shaping signal built on the boxes would actually get
    out["box.mean_iou_all"] = sum(ious) / len(boxes) if boxes else math.nan
    out["box.centre_error_px"] = nanmean(centre)

    mcqs = [p.mcq_result for p in ordered]
    out["mcq.accuracy"] = metrics.mcq_accuracy([m.label if m.ok else None for m in mcqs],
                                               [p.truth.label for p in ordered])
    return out


def empty_sweep_statistics() -> dict[str, float]:
    """The sweep statistics' keys, all NaN (n/a): for runs that probe no sweep."""
    return {k: math.nan for k in sweep_statistics([])}
