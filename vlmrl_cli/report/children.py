"""The training runs behind a sweep's jobs, one row each, printed by ``vlmrl run`` (and ``--dry-run``)
so that ``vlmrl evaluate RUN_ID`` always has an id to take."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from vlmrl_cli.analysis.thresholds import steps_to_threshold
from vlmrl_cli.tracking import schema
from vlmrl_cli.training.config import TrainJob

TOP_THRESHOLD = -130.0


@dataclass(frozen=True)
class ChildRow:
    """One job's run: its id and status (``-`` and ``not run`` when the store has none), steps to
    the top threshold (NaN: not reached, or no run) and its detached success rate."""

    arm: str
    seed: int
    run_id: str
    status: str
    steps: float
    detached_success: float


def _steps(client: Any, run_id: str, threshold: float, window: int) -> float:
    points = sorted(client.get_metric_history(run_id, schema.METRIC_NATIVE_RETURN),
                    key=lambda p: (p.step, p.timestamp))
    hit = steps_to_threshold([p.step for p in points], [p.value for p in points], threshold, window)
    return math.nan if hit is None else float(hit)


def _pick(runs: Iterable[Any]) -> Any | None:
    """The run a job stands for: its newest FINISHED run, else its newest attempt."""
    ordered = sorted(runs, key=lambda r: r.info.start_time or 0, reverse=True)
    return next((r for r in ordered if r.info.status == "FINISHED"), ordered[0] if ordered else None)


def child_rows(client: Any, experiment_id: str, jobs: Sequence[TrainJob], threshold: float = TOP_THRESHOLD,
               window: int = 100) -> list[ChildRow]:
    """One row per job, from the experiment's training runs (matched by arm, seed and config hash)."""
    by_key = schema.train_runs_by_job(client, experiment_id)
    rows = []
    for job in jobs:
        run = _pick(by_key.get((job.arm.name, str(job.seed), job.config_hash), []))
        if run is None:
            rows.append(ChildRow(job.arm.name, job.seed, "-", "not run", math.nan, math.nan))
            continue
        finished = run.info.status == "FINISHED"
        rows.append(ChildRow(job.arm.name, job.seed, run.info.run_id, run.info.status,
                             _steps(client, run.info.run_id, threshold, window) if finished else math.nan,
                             float(run.data.metrics.get(schema.METRIC_EVAL_SUCCESS_RATE, math.nan))))
    return rows


def children_of(client: Any, parent: Any) -> list[ChildRow]:
    """The training runs a sweep's parent run created itself (not those it found FINISHED), by arm and seed."""
    found = schema.search_all(client, parent.info.experiment_id,
                              schema.runs_filter({schema.MLFLOW_PARENT_RUN_ID: parent.info.run_id}))
    rows = [ChildRow(r.data.tags.get(schema.TAG_ARM, "?"), int(r.data.tags.get(schema.TAG_SEED, "-1")),
                     r.info.run_id, r.info.status, math.nan,
                     float(r.data.metrics.get(schema.METRIC_EVAL_SUCCESS_RATE, math.nan))) for r in found]
    return sorted(rows, key=lambda r: (r.arm, r.seed))


def format_rows(rows: Sequence[ChildRow], threshold: float = TOP_THRESHOLD) -> list[list[str]]:
    """The rows as table cells: arm, seed, run id, status, steps to ``threshold``, detached success."""
    def steps(r: ChildRow) -> str:
        if r.status != "FINISHED":
            return "-"
        return f"{r.steps:,.0f}" if math.isfinite(r.steps) else "not reached"

    return [[r.arm, str(r.seed), r.run_id, r.status, steps(r),
             f"{r.detached_success:.0%}" if math.isfinite(r.detached_success) else "-"] for r in rows]


def header(threshold: float = TOP_THRESHOLD) -> list[str]:
    """The table's header for a task whose top reward threshold is ``threshold``."""
    return ["arm", "seed", "run id", "status", f"steps to {threshold:g}", "detached"]
