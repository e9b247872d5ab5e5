"""The taxonomy probe (paper Section 2, Table 1, Figure 1): ask a VLM about frames, score it.

Every probed frame gets all three prompts (float regression, box grounding, semantic MCQ);
the answers are parsed, compared with the geometric ground truth, and turned into the
potential Phi each answer would give PBRS, so that the paper's consequences (noise, ROI
instability, the MCQ dead zone) are computed rather than asserted.

``run_taxonomy`` is the one entry point. It validates everything the user can get wrong
(output folder, backend, transcript, tracking store) before probing, writes its files into a
temporary sibling folder that is moved into place only when everything succeeded, and logs
exactly one MLflow run, marked FAILED if the probe fails after it was created.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vlmrl_cli.core.errors import BadInput, MissingAnswer
from vlmrl_cli.core.provenance import config_hash, flatten
from vlmrl_cli.frames.geometry import MAX_POSITION, MIN_POSITION, GroundTruth
from vlmrl_cli.frames.render import Frame, FrameRenderer
from vlmrl_cli.probe import metrics
from vlmrl_cli.probe.parsers import (
    BoxResult,
    FloatResult,
    MCQResult,
    ParseStatus,
    parse_box,
    parse_float,
    parse_mcq,
)
from vlmrl_cli.tracking import store
from vlmrl_cli.vlm.base import Backend
from vlmrl_cli.vlm.client import VLMClient
from vlmrl_cli.vlm.config import VLMConfig
from vlmrl_cli.vlm.prompts import PROMPTS, PromptKind
from vlmrl_cli.vlm.registry import build_client

DEFAULT_STATES = 25
# The paper's Figure 1 pair: (panel, x, caption). Always probed, whatever the sweep.
PAPER_FRAMES: tuple[tuple[str, float, str], ...] = (
    ("a", -0.50, "Absolute valley"),
    ("b", -0.69, "Lower left slope"),
)
ProgressFn = Callable[[int, int], None]


@dataclass(frozen=True)
class TaxonomyConfig:
    """Everything ``vlmrl taxonomy`` needs, passed whole and logged whole."""

    vlm: VLMConfig = field(default_factory=VLMConfig, metadata={"help": "which VLM answers"})
    states: int | None = field(
        default=DEFAULT_STATES,
        metadata={"help": "sweep positions evenly spaced over the track (>= 2); None: replay's frames only"},
    )
    out: Path = field(default=Path("results/taxonomy/sim"), metadata={"help": "output folder"})
    tracking_uri: str | None = field(default=None, metadata={"help": "MLflow tracking URI"})
    experiment: str = field(default="vlmrl-taxonomy", metadata={"help": "MLflow experiment name"})

    def __post_init__(self) -> None:
        if self.states is not None and self.states < 2:
            raise BadInput(f"--states {self.states} is too few: a sweep needs at least 2 positions.")


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


@dataclass(frozen=True)
class TaxonomyResult:
    """What a finished probe produced and where it went."""

    out: Path
    run_id: str
    backend_label: str
    simulated: bool
    provenance: str
    probes: tuple[FrameProbe, ...]
    sweep: Mapping[str, float]
    files: tuple[Path, ...]
    queries: int
    cache_hits: int
    cache_misses: int

    def panel(self, name: str) -> FrameProbe | None:
        return next((p for p in self.probes if p.panel == name), None)


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
        float_result=parse_float(answers[PromptKind.FLOAT]),
        box_result=parse_box(answers[PromptKind.BOX]),
        mcq_result=parse_mcq(answers[PromptKind.MCQ]),
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
            vlm.append(metrics.position_potential(p.float_result.value if p.float_result.ok else None))
            true.append(metrics.position_potential(p.truth.x))
        elif kind is PromptKind.BOX:
            vlm.append(metrics.box_potential(p.box_result.box if p.box_result.ok else None))
            true.append(metrics.box_potential(p.truth.box_px))
        else:
            vlm.append(metrics.label_potential(p.mcq_result.label if p.mcq_result.ok else None))
            true.append(metrics.label_potential(p.truth.zone))
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


# --- provenance wording ----------------------------------------------------------------------

def provenance_line(backend: Backend) -> str:
    """One sentence saying where the answers came from (shown in captions and tables)."""
    if backend.simulated:
        return ("SIMULATED VLM (not a real model): answers come from a pixel reader with a coarse patch "
                "grid and injected noise, not from a vision-language model.")
    records = getattr(backend, "records", ())
    if backend.name == "replay" and any(r.backend == "paper" for r in records):
        return ("The VLM outputs are the paper's reported raw outputs (its Table 1), replayed from a "
                "transcript transcribed from the paper, not produced here; truths and dPhi are computed here.")
    if backend.name == "replay":
        source = getattr(backend, "source", None)
        return f"Answers replayed from the transcript {source}."
    return "Live answers of a real VLM."


def _figure_note(backend: Backend) -> str:
    if backend.name == "replay" and any(r.backend == "paper" for r in getattr(backend, "records", ())):
        return "the paper's reported raw outputs, replayed"
    return ""


# --- output folder ---------------------------------------------------------------------------

def _staging_folder(out: Path) -> Path:
    """Check ``out`` can be written and make the temporary sibling the results are staged in."""
    if out.exists() and not out.is_dir():
        raise BadInput(f"--out {out} is a file; pass a folder.")
    if out.exists() and not os.access(out, os.W_OK):
        raise BadInput(f"--out {out} is not writable; pass a folder you can write to.")
    parent = out.resolve().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        return Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=parent))
    except OSError as exc:
        raise BadInput(f"cannot write the output folder {out} ({exc.strerror}); pass a writable --out.") from exc


def _move_into_place(staging: Path, out: Path) -> tuple[Path, ...]:
    try:
        out.mkdir(parents=True, exist_ok=True)
        moved = []
        for item in sorted(staging.iterdir()):
            target = out / item.name
            os.replace(item, target)
            moved.append(target)
    except OSError as exc:
        raise BadInput(f"cannot move the results into {out} ({exc.strerror}); pass a writable --out.") from exc
    return tuple(moved)


def _jsonable(values: Mapping[str, float]) -> dict[str, float | None]:
    return {k: (v if math.isfinite(v) else None) for k, v in values.items()}


# --- the probe -------------------------------------------------------------------------------

def run_taxonomy(cfg: TaxonomyConfig, progress: ProgressFn | None = None) -> TaxonomyResult:
    """Probe, score, write Table 1 and Figure 1 into ``cfg.out`` and log one MLflow run.

    ``progress(done, total)`` is called after each frame. User errors are ``BadInput``,
    raised before any result file exists in ``cfg.out``.
    """
    from vlmrl_cli.probe.figure1 import save_figure1
    from vlmrl_cli.probe.table1 import write_tables

    staging = _staging_folder(cfg.out)
    client: VLMClient | None = None
    try:
        client = build_client(cfg.vlm, transcript=staging / "transcript.jsonl")
        backend = client.backend
        tracker = store.connect(cfg.tracking_uri)
        experiment_id = store.ensure_experiment(tracker, cfg.experiment)
        planned, is_sweep = plan_frames(cfg.states, backend)
        run_name = f"taxonomy-{backend.name}-{cfg.states if is_sweep else 'transcript'}-{config_hash(cfg)[:6]}"
        run = tracker.create_run(experiment_id, run_name=run_name)
        run_id = str(run.info.run_id)
        try:
            store.set_tags(tracker, run_id, {
                **store.provenance_tags(client.label, backend.simulated),
                f"{store.TAG_PREFIX}command": "taxonomy",
                f"{store.TAG_PREFIX}config_hash": config_hash(cfg),
            })
            store.log_params(tracker, run_id, _params(cfg, backend, len(planned), is_sweep))
            probes = _probe_all(client, planned, progress)
            sweep = sweep_statistics(probes) if is_sweep else empty_sweep_statistics()
            label = client.label
            provenance = provenance_line(backend)
            plain = f"{backend.name}:{backend.model}"
            write_tables(probes, sweep, staging, label=plain, provenance=provenance, simulated=backend.simulated)
            save_figure1(probes, staging / "figure1.png", label=plain, simulated=backend.simulated,
                         note=_figure_note(backend))
            stats = client.stats
            summary: dict[str, Any] = {
                "backend": backend.name, "model": backend.model, "simulated": backend.simulated,
                "label": label, "provenance": provenance, "sweep": is_sweep,
                "queries": stats.queries, "cache_hits": stats.cache_hits, "cache_misses": stats.cache_misses,
                "metrics": _jsonable(sweep),
            }
            (staging / "metrics.json").write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n",
                                                  encoding="utf-8")
            client.close()  # flushes the transcript before it is logged
            client = None
            logged = {f"taxonomy.{k}": v for k, v in sweep.items() if math.isfinite(v)}
            logged.update({"taxonomy.cache_hits": stats.cache_hits, "taxonomy.cache_misses": stats.cache_misses,
                           "taxonomy.frames": len(probes)})
            batch = store.BatchLogger(tracker, run_id)
            batch.log(logged, step=0)
            batch.flush()
            store.log_artifacts(tracker, run_id, sorted(staging.iterdir()))
            files = _move_into_place(staging, cfg.out)
        except KeyboardInterrupt:
            tracker.set_terminated(run_id, "KILLED")
            raise
        except BaseException:
            tracker.set_terminated(run_id, "FAILED")
            raise
        tracker.set_terminated(run_id, "FINISHED")
        return TaxonomyResult(
            out=cfg.out, run_id=run_id, backend_label=label, simulated=backend.simulated,
            provenance=provenance, probes=tuple(probes), sweep=sweep, files=files,
            queries=stats.queries, cache_hits=stats.cache_hits, cache_misses=stats.cache_misses,
        )
    finally:
        if client is not None:
            client.close()
        shutil.rmtree(staging, ignore_errors=True)


def _probe_all(client: VLMClient, planned: list[_Planned], progress: ProgressFn | None) -> list[FrameProbe]:
    probes = []
    with FrameRenderer() as renderer:
        for i, item in enumerate(planned, start=1):
            probes.append(probe_frame(client, renderer, item))
            if progress is not None:
                progress(i, len(planned))
    return probes


def _params(cfg: TaxonomyConfig, backend: Backend, frames: int, is_sweep: bool) -> dict[str, str]:
    params = flatten(cfg)
    params.update({
        "backend": backend.name,
        "model": backend.model,
        "simulated": str(backend.simulated).lower(),
        "frames": str(frames),
        "sweep": str(is_sweep).lower(),
    })
    for kind, prompt in PROMPTS.items():
        params[f"prompt.{kind.value}"] = prompt.text
    return params
