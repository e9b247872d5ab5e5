"""The taxonomy probe (paper Section 2, Table 1, Figure 1). See docs/commands/taxonomy.md."""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from collections.abc import Mapping
from contextlib import closing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.core.names import experiment_problem, tracking_uri_problem
from vlmrl_cli.core.paths import check_out_folder
from vlmrl_cli.core.provenance import config_hash, flatten
from vlmrl_cli.probe.milestones import ProgressFn, generated_too, mcq_probe, probe_milestones, write_milestones
from vlmrl_cli.probe.scoring import (
    DEFAULT_STATES,
    FrameProbe,
    _Planned,
    empty_sweep_statistics,
    number_probe,
    plan_frames,
    probe_frame,
    sweep_statistics,
    table1_prompts,
)
from vlmrl_cli.probe.states import states_problem
from vlmrl_cli.tasks.base import Task
from vlmrl_cli.tracking import schema, store
from vlmrl_cli.tracking.lifecycle import tracked_run
from vlmrl_cli.vlm.base import Backend
from vlmrl_cli.vlm.client import VLMClient
from vlmrl_cli.vlm.config import VLMConfig, profile_problem
from vlmrl_cli.vlm.preflight import check_vlm
from vlmrl_cli.vlm.prompts import PromptKind
from vlmrl_cli.vlm.registry import build_client


@dataclass(frozen=True)
class TaxonomyConfig:
    """Everything ``vlmrl taxonomy`` needs, passed whole and logged whole."""

    vlm: VLMConfig = field(default_factory=VLMConfig, metadata={"help": "which VLM answers"})
    states: int | None = field(
        default=DEFAULT_STATES,
        metadata={"help": "sweep readings evenly spaced over the task's range (>= 2); None: replay's frames only"},
    )
    out: Path = field(default=Path("results/taxonomy/sim"), metadata={"help": "output folder"})
    tracking_uri: str | None = field(default=None, metadata={"help": "MLflow tracking URI"})
    experiment: str = field(default="vlmrl-taxonomy", metadata={"help": "MLflow experiment name"})

    def __post_init__(self) -> None:
        problem = (states_problem(self.states) if self.states is not None else None) or \
            experiment_problem(self.experiment) or tracking_uri_problem(self.tracking_uri)
        if problem:
            raise BadInput(problem + ".")


@dataclass(frozen=True)
class TaxonomyResult:
    """What a finished probe produced: ``FrameProbe``s (``sweep``) or else ``MilestoneProbe``s."""

    out: Path
    run_id: str
    backend_label: str
    simulated: bool
    probes: tuple[Any, ...]
    sweep: Mapping[str, float]
    files: tuple[Path, ...]
    queries: int
    cache_hits: int
    cache_misses: int
    metrics: Mapping[str, Any] = field(default_factory=dict)

    def panel(self, name: str) -> FrameProbe | None:
        return next((p for p in self.probes if p.panel == name), None)


def provenance_line(backend: Backend) -> str:
    """One sentence saying where the answers came from (shown in captions and tables)."""
    if backend.simulated:
        return ("SIMULATED VLM (not a real model): answers come from a pixel reader with a coarse patch "
                "grid and injected noise, not from a vision-language model.")
    if _replays_paper(backend):
        return ("The VLM outputs are the paper's reported raw outputs (its Table 1), replayed from a "
                "transcript transcribed from the paper, not produced here; truths and dPhi are computed here.")
    if backend.name == "replay":
        return f"Answers replayed from the transcript {getattr(backend, 'source', None)}."
    return "Live answers of a real VLM."


def _replays_paper(backend: Backend) -> bool:
    return backend.name == "replay" and any(r.backend == "paper" for r in getattr(backend, "records", ()))


def _staging_folder(out: Path) -> Path:
    """The temporary sibling of ``out`` the results are staged in, moved into place on success."""
    check_out_folder(out)
    parent = out.resolve().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        return Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=parent))
    except OSError as exc:
        raise BadInput(f"cannot write the output folder {out} ({exc.strerror}); pass a writable --out.") from exc


def _move_into_place(staging: Path, out: Path) -> tuple[Path, ...]:
    try:
        out.mkdir(parents=True, exist_ok=True)
        names = sorted(item.name for item in staging.iterdir())
        for name in names:
            os.replace(staging / name, out / name)
    except OSError as exc:
        raise BadInput(f"cannot move the results into {out} ({exc.strerror}); pass a writable --out.") from exc
    return tuple(out / name for name in names)


#: What one kind of probe found: probes, sweep statistics, ``metrics.json`` and MLflow metrics.
_Outcome = tuple[tuple[Any, ...], Mapping[str, float], dict[str, Any], dict[str, float]]


class _NumberTable:
    """Table 1 of a task with number questions on a sweep; its run is hashed by the config alone."""

    def __init__(self, cfg: TaxonomyConfig, task: Task, backend: Backend) -> None:
        self.task = task
        self.planned, self.is_sweep = plan_frames(cfg.states, backend, number_probe(task))
        key = config_hash(cfg)
        self.run_name = f"taxonomy-{backend.name}-{cfg.states if self.is_sweep else 'transcript'}-{key[:6]}"
        self.tags = {schema.TAG_CONFIG_HASH: key}
        self.params = {**flatten(cfg), "backend": backend.name, "model": backend.model,
                       "simulated": str(backend.simulated).lower(), "frames": str(len(self.planned)),
                       "sweep": str(self.is_sweep).lower(),
                       **{f"prompt.{kind.value}": prompt.text for kind, prompt in table1_prompts(task).items()}}

    def probe(self, client: VLMClient, staging: Path, progress: ProgressFn | None) -> _Outcome:
        from vlmrl_cli.probe.figure1 import save_figure1
        from vlmrl_cli.probe.table1 import write_tables

        probes = _probe_all(client, self.task, self.planned, progress)
        sweep = sweep_statistics(probes) if self.is_sweep else empty_sweep_statistics()
        both = _generated_too(client, self.task, self.planned, probes)
        backend, stats = client.backend, client.stats
        provenance, plain = provenance_line(backend), f"{backend.name}:{backend.model}"
        write_tables(probes, sweep, staging, number_probe(self.task), label=plain, provenance=provenance,
                     simulated=backend.simulated)
        save_figure1(probes, staging / "figure1.png", label=plain, simulated=backend.simulated,
                     note="the paper's reported raw outputs, replayed" if _replays_paper(backend) else "")
        summary: dict[str, Any] = {
            "backend": backend.name, "model": backend.model, "simulated": backend.simulated,
            "label": client.label, "provenance": provenance, "sweep": self.is_sweep,
            "queries": stats.queries, "cache_hits": stats.cache_hits, "cache_misses": stats.cache_misses,
            "metrics": {k: (v if math.isfinite(v) else None) for k, v in sweep.items()},
            **client.mcq_mode_entry(self.task.milestones.prompt), **both,
        }
        (staging / "metrics.json").write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n", encoding="utf-8")
        logged = {f"taxonomy.{k}": v for k, v in sweep.items() if math.isfinite(v)}
        logged.update({"taxonomy.cache_hits": stats.cache_hits, "taxonomy.cache_misses": stats.cache_misses,
                       "taxonomy.frames": len(probes)})
        logged.update({f"taxonomy.{k}": v for k, v in both.items() if math.isfinite(v)})
        return tuple(probes), sweep, summary, logged


class _MilestoneTable:
    """Table 1 of a task without numbers: its MCQ; its run is hashed by the task, states and VLM."""

    def __init__(self, cfg: TaxonomyConfig, task: Task, backend: Backend) -> None:
        self.task, self.states = task, cfg.states or DEFAULT_STATES
        ident = {"task": task.name, "states": self.states, "vlm": cfg.vlm}
        self.run_name = f"taxonomy-{task.name}-{backend.name}-{self.states}"
        self.tags = {schema.TAG_TASK: task.name, schema.TAG_CONFIG_HASH: config_hash(ident)}
        self.params = {**flatten(ident), "prompt.mcq": task.milestones.prompt.text}

    def probe(self, client: VLMClient, staging: Path, progress: ProgressFn | None) -> _Outcome:
        probes, frames = probe_milestones(client, self.task, self.states, progress)
        values, logged = write_milestones(staging, self.task, client, probes, frames)
        return tuple(probes), {}, values, logged


def _check(cfg: TaxonomyConfig, task: Task) -> None:
    """``BadInput`` for what can be wrong before anything exists (task, profile, folder, VLM)."""
    if task.numbers is None and task.probe_states is None:
        raise BadInput(f"task '{task.name}' names no probe states; give its Task a probe_states function.")
    problem = profile_problem(cfg.vlm.sim.profile, task) if cfg.vlm.backend == "sim" else None
    if problem:
        raise BadInput(problem + ".")
    check_out_folder(cfg.out)
    check_vlm(cfg.vlm)


def run_taxonomy(cfg: TaxonomyConfig, progress: ProgressFn | None = None, task: Task | None = None) -> TaxonomyResult:
    """Probe ``task``'s frames (None: the paper's), write Table 1 and Figure 1 into ``cfg.out`` and log
    one MLflow run; user errors are ``BadInput``, raised before any result file exists."""
    if task is None:
        from vlmrl_cli.tasks.registry import paper_task

        task = paper_task()
    _check(cfg, task)
    tracker = store.connect(cfg.tracking_uri)
    staging = _staging_folder(cfg.out)
    client: VLMClient | None = None
    try:
        transcript = staging / "transcript.jsonl" if task.numbers is not None else None
        client = build_client(cfg.vlm, transcript=transcript, reader=task.reader)
        backend, label = client.backend, client.label
        kind = (_NumberTable if task.numbers is not None else _MilestoneTable)(cfg, task, backend)
        experiment_id = store.ensure_experiment(tracker, cfg.experiment)
        run_id = str(tracker.create_run(experiment_id, run_name=kind.run_name).info.run_id)
        with tracked_run(tracker, run_id):
            store.set_tags(tracker, run_id, {**store.provenance_tags(label, backend.simulated),
                                             schema.TAG_COMMAND: schema.COMMAND_TAXONOMY, **kind.tags})
            store.log_params(tracker, run_id, kind.params)
            probes, sweep, metrics, logged = kind.probe(client, staging, progress)
            stats = client.stats
            client.close()  # flushes the transcript before it is logged
            client = None
            batch = store.BatchLogger(tracker, run_id)
            batch.log(logged, step=0)
            batch.flush()
            store.log_artifacts(tracker, run_id, sorted(staging.iterdir()))
            files = _move_into_place(staging, cfg.out)
        return TaxonomyResult(
            out=cfg.out, run_id=run_id, backend_label=label, simulated=backend.simulated,
            probes=probes, sweep=sweep, files=files,
            queries=stats.queries, cache_hits=stats.cache_hits, cache_misses=stats.cache_misses,
            metrics=metrics,
        )
    finally:
        if client is not None:
            client.close()
        shutil.rmtree(staging, ignore_errors=True)


def _probe_all(client: VLMClient, task: Task, planned: list[_Planned], progress: ProgressFn | None
               ) -> list[FrameProbe]:
    probes = []
    with closing(number_probe(task).renderer()) as renderer:
        for i, item in enumerate(planned, start=1):
            probes.append(probe_frame(client, task, renderer, item))
            if progress is not None:
                progress(i, len(planned))
    return probes


def _generated_too(client: VLMClient, task: Task, planned: list[_Planned], probes: list[FrameProbe]
                   ) -> dict[str, float]:
    """``milestones.generated_too`` on the same frames, drawn again."""
    if not client.scores(task.milestones.prompt) or not planned:
        return {}
    with closing(number_probe(task).renderer()) as renderer:
        frames = [renderer.render(item.x, frame_id=item.frame_id) for item in planned]
    scored = [mcq_probe(p.frame_id, str(p.truth.label), p.answers[PromptKind.MCQ], task.milestones.labels)
              for p in probes]
    return generated_too(client, task, scored, frames)
