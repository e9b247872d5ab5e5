"""The milestone MCQ of the taxonomy probe, and Table 1 of a task without ``Task.numbers``."""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from vlmrl_cli.core import tables
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.probe import metrics
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.tasks.base import Task
from vlmrl_cli.vlm.client import VLMClient
from vlmrl_cli.vlm.parsers import ParseStatus, parse_mcq

ProgressFn = Callable[[int, int], None]
NOT_DEFINED = "not defined for this task (no position or box answer key)"


@dataclass(frozen=True)
class MilestoneProbe:
    """One probed state: its id, true label, the raw answer, the parsed label (None: unparsed)."""

    frame_id: str
    truth: str
    answer: str | None
    label: str | None
    status: ParseStatus


@dataclass(frozen=True)
class MilestoneSummary:
    """MCQ accuracy (with a Wilson interval over frames), format failures and the potential error."""

    frames: int
    correct: int
    accuracy: float
    accuracy_low: float
    accuracy_high: float
    format_failure_rate: float
    mean_abs_dphi: float


def summarize(probes: list[MilestoneProbe], potentials: dict[str, float], ci: float = 0.95) -> MilestoneSummary:
    """The MCQ row of Table 1: accuracy with its Wilson interval, format failures, mean ``|dPhi|``."""
    n = len(probes)
    correct = sum(p.label == p.truth for p in probes)
    accuracy = metrics.mcq_accuracy([p.label for p in probes], [p.truth for p in probes])
    if n:
        interval = stats.binomtest(correct, n).proportion_ci(confidence_level=ci, method="wilson")
        low, high = float(interval.low), float(interval.high)
    else:
        low = high = math.nan
    parsed = [p for p in probes if p.label is not None]
    dphi = [abs(potentials[p.label] - potentials[p.truth]) for p in parsed if p.label in potentials]
    return MilestoneSummary(n, correct, accuracy, low, high, metrics.format_failure_rate(p.status for p in probes),
                            float(np.mean(dphi)) if dphi else math.nan)


def mcq_probe(frame_id: str, truth: str, answer: str | None, labels: Sequence[str]) -> MilestoneProbe:
    """One answer to the MCQ, parsed in ``labels``."""
    parsed = parse_mcq(answer, labels)
    return MilestoneProbe(frame_id, truth, answer, str(parsed.label) if parsed.ok and parsed.label is not None
                          else None, parsed.status)


def potentials_of(task: Task) -> dict[str, float]:
    return {str(label): float(p) for label, p in task.label_potentials}


def probe_milestones(client: VLMClient, task: Task, states: int, progress: ProgressFn | None
                     ) -> tuple[list[MilestoneProbe], list[Frame]]:
    """The probes of ``task``'s MCQ on about ``states`` states (``Task.probe_states``), and the frames."""
    camera = task.camera.make(ShapingConfig(label_potentials=task.label_potentials))
    probes, shown = [], []
    try:
        planned = task.probe_states(states) if task.probe_states is not None else []
        for i, state in enumerate(planned, start=1):
            vector = isinstance(state, np.ndarray)  # else a simulator of the task's own
            sim = SimpleNamespace(state=np.asarray(state, dtype=float)) if vector else state
            view = camera.look(sim)
            frame = view.frame()
            values = np.asarray(state, dtype=float).reshape(-1) if vector else ()
            frame_id = ("state=[" + ", ".join(f"{v:+.3f}" for v in values) + "]" if vector
                        else f"{task.name}-{i:04d}-{view.key[:12]}")
            probes.append(mcq_probe(frame_id, task.truth(sim), client.ask(task.milestones.prompt, frame).text,
                                    task.milestones.labels))
            shown.append(frame)
            if progress is not None:
                progress(i, len(planned))
    finally:
        camera.close()
    return probes, shown


def write_milestones(out: Path, task: Task, client: VLMClient, probes: list[MilestoneProbe], frames: list[Frame]
                     ) -> tuple[dict[str, Any], dict[str, float]]:
    """Write Table 1, probes.csv, figure1.png and metrics.json into ``out``; (metrics, MLflow metrics)."""
    summary = summarize(probes, potentials_of(task))
    both = generated_too(client, task, probes, frames)
    backend = client.backend
    label = f"{backend.name}:{backend.model}"
    simulated = bool(backend.simulated)
    _write(out, task, probes, summary, label, simulated)
    _figure(out / "figure1.png", task, probes, frames, label, simulated)
    values = {"task": task.name, "backend": backend.name, "model": backend.model,
               "simulated": simulated, "frames": summary.frames, "mcq.accuracy": summary.accuracy,
               "mcq.accuracy_low": summary.accuracy_low, "mcq.accuracy_high": summary.accuracy_high,
               "mcq.format_failure_rate": summary.format_failure_rate,
               "mcq.mean_abs_dphi": summary.mean_abs_dphi,
               **client.mcq_mode_entry(task.milestones.prompt), **both}
    (out / "metrics.json").write_text(json.dumps(values, indent=2) + "\n", encoding="utf-8")
    logged = {f"taxonomy.{k}": float(v) for k, v in values.items() if isinstance(v, float) and math.isfinite(v)}
    return values, logged


def generated_too(client: VLMClient, task: Task, probes: list[MilestoneProbe], frames: Sequence[Frame]
                  ) -> dict[str, float]:
    """Where the MCQ was scored, the same frames generated too (``mcq.generate.*``, ``mcq.modes_agree``)."""
    prompt = task.milestones.prompt
    if not client.scores(prompt) or not frames:
        return {}
    generated = [mcq_probe(p.frame_id, p.truth, a.text, task.milestones.labels)
                 for p, a in zip(probes, client.ask_many(prompt, frames, generate=True), strict=True)]
    s = summarize(generated, potentials_of(task))
    agree = sum(a.label == b.label for a, b in zip(probes, generated, strict=True)) / len(probes)
    return {"mcq.generate.accuracy": s.accuracy, "mcq.generate.format_failure_rate": s.format_failure_rate,
            "mcq.generate.mean_abs_dphi": s.mean_abs_dphi, "mcq.modes_agree": agree}


def _write(out: Path, task: Task, probes: list[MilestoneProbe], s: MilestoneSummary, label: str,
           simulated: bool) -> None:
    rows = [
        {"prompt": "I float regression", "frames": 0, "result": NOT_DEFINED},
        {"prompt": "II box grounding", "frames": 0, "result": NOT_DEFINED},
        {"prompt": "III semantic MCQ", "frames": s.frames,
         "result": f"accuracy {s.accuracy:.2f} [{s.accuracy_low:.2f}, {s.accuracy_high:.2f}] ({s.correct}/{s.frames}); "
                   f"format failures {s.format_failure_rate:.2f}; mean |dPhi| {s.mean_abs_dphi:.3f}"},
    ]
    pd.DataFrame(rows).assign(task=task.name, vlm=label, simulated=simulated).to_csv(out / "table1.csv", index=False)
    text = [f"# Table 1 for task {task.name}: the milestone MCQ of {label}", ""]
    if simulated:
        text += ["> **SIMULATED VLM (not a real model): answers from a pixel reader with noise.**", ""]
    text += [f"{task.summary}. Labels (low to high): {', '.join(task.milestones.labels)}; potentials "
             + ", ".join(f"{lab}={p:g}" for lab, p in task.label_potentials) + ".", "",
             f"Prompt: \"{task.milestones.prompt.text}\"", "",
             *tables.markdown_rows(["prompt", "frames", "result"], [[r["prompt"], r["frames"], r["result"]]
                                                                   for r in rows]),
             "", "Accuracy counts an unparsed answer as wrong; its interval is Wilson's over frames (95%).", ""]
    confusion = pd.crosstab(pd.Series([p.truth for p in probes], name="truth"),
                            pd.Series([p.label or "(unparsed)" for p in probes], name="answer"))
    text += ["Confusion (rows: truth, columns: answer):", "",
             *tables.markdown_rows(["truth", *confusion.columns],
                                   [[i, *r] for i, r in zip(confusion.index, confusion.to_numpy(), strict=True)]),
             ""]
    (out / "table1.md").write_text("\n".join(text), encoding="utf-8")
    pd.DataFrame([{"frame_id": p.frame_id, "truth": p.truth, "answer": p.answer, "label": p.label,
                   "status": p.status.value} for p in probes]).assign(vlm=label).to_csv(out / "probes.csv", index=False)


def _figure(path: Path, task: Task, probes: list[MilestoneProbe], frames: list[Any], label: str,
            simulated: bool) -> None:
    """Figure 1 of a task: the first probed frame of each true label, with its answer."""
    from matplotlib.figure import Figure

    picks = [next(i for i, p in enumerate(probes) if p.truth == lab) for lab in task.milestones.labels
             if any(p.truth == lab for p in probes)]
    fig = Figure(figsize=(2.6 * max(len(picks), 1), 3.2), layout="constrained")
    axes = fig.subplots(1, max(len(picks), 1), squeeze=False)[0]
    for ax, i in zip(axes, picks, strict=False):
        ax.imshow(frames[i].pixels)
        ax.set_axis_off()
        probe = probes[i]
        ax.set_title(f"truth {probe.truth}\nVLM: {probe.label or '(' + probe.status.value + ')'}", fontsize=8)
    title = f"Figure 1 ({task.name}): milestone MCQ, {label}"
    fig.suptitle(title + ("\nSIMULATED VLM (not a real model)" if simulated else ""), fontsize=9,
                 color="darkred" if simulated else "black")
    fig.savefig(path, dpi=120)
