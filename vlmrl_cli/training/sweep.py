"""Run every (arm, seed) job of a ``RunConfig`` in worker processes, resumably.

Resume rule: a job whose (arm, seed, config hash) already has a FINISHED run in the experiment
is skipped; runs of a pending job left RUNNING by a crash or Ctrl-C are marked FAILED first
and the job is trained again. One parent run records each invocation that trains anything.
"""

from __future__ import annotations

import dataclasses
import multiprocessing as mp
import queue as queue_mod
import signal
import threading
import time
from collections.abc import Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from vlmrl_cli.core.provenance import config_hash, flatten
from vlmrl_cli.shaping.arms import ARMS
from vlmrl_cli.tracking import schema, store
from vlmrl_cli.training.config import RunConfig, TrainJob
from vlmrl_cli.training.events import JobResult, ProgressEvent
from vlmrl_cli.training.worker import init_worker, train_job


class SweepReporter(Protocol):
    """What the sweep tells its caller (the CLI draws it with rich)."""

    def planned(self, pending: list[TrainJob], done: list[TrainJob]) -> None: ...

    def progress(self, event: ProgressEvent) -> None: ...

    def finished(self, result: JobResult) -> None: ...


@dataclass
class SweepSummary:
    parent_run_id: str | None
    experiment_id: str
    skipped: list[str] = field(default_factory=list)
    marked_failed: list[str] = field(default_factory=list)
    results: list[JobResult] = field(default_factory=list)
    wall_s: float = 0.0

    @property
    def failed(self) -> list[JobResult]:
        return [r for r in self.results if r.status != "FINISHED"]


def vlm_identity(cfg: RunConfig) -> tuple[str, bool]:
    """The VLM label and simulated flag of the sweep, checking the backend answers at all
    (unreachable server, missing model: ``BadInput`` before anything trains)."""
    if not any(ARMS[name].uses_vlm for name in cfg.arms):
        return "none (no arm uses a VLM)", False
    from vlmrl_cli.vlm.base import describe
    from vlmrl_cli.vlm.registry import build_backend

    backend = build_backend(cfg.vlm)
    try:
        return describe(backend), bool(backend.simulated)
    finally:
        backend.close()


def plan(client: Any, experiment_id: str, jobs: list[TrainJob]) -> tuple[list[TrainJob], list[TrainJob], list[Any]]:
    """Split jobs into (pending, done) and list the stale RUNNING runs of pending jobs."""
    by_key: dict[tuple[str, str, str], list[Any]] = {}
    for run in schema.search_all(client, experiment_id, schema.runs_filter({schema.TAG_KIND: schema.KIND_TRAIN})):
        t = run.data.tags
        key = (t.get(schema.TAG_ARM, ""), t.get(schema.TAG_SEED, ""), t.get(schema.TAG_CONFIG_HASH, ""))
        by_key.setdefault(key, []).append(run)
    pending: list[TrainJob] = []
    done: list[TrainJob] = []
    stale: list[Any] = []
    for job in jobs:
        runs = by_key.get((job.arm.name, str(job.seed), job.config_hash), [])
        if any(r.info.status == "FINISHED" for r in runs):
            done.append(job)
        else:
            pending.append(job)
            stale.extend(r for r in runs if r.info.status in ("RUNNING", "SCHEDULED"))
    return pending, done, stale


@dataclass(frozen=True)
class DryPlan:
    """What a sweep would do, read without writing: ``done`` jobs already have a FINISHED run."""

    pending: list[TrainJob]
    done: list[TrainJob]
    note: str  # where the answer came from (or why every job is pending)


def dry_plan(cfg: RunConfig) -> DryPlan:
    """Plan ``cfg``'s jobs against the store, read-only: a sqlite store that does not exist is
    not created, a missing experiment is not created, stale runs are not touched."""
    uri = store.resolve_tracking_uri(cfg.tracking_uri)
    jobs = cfg.jobs()
    if uri.startswith("sqlite:///") and not Path(uri.removeprefix("sqlite:///")).exists():
        return DryPlan(jobs, [], f"the tracking store {uri} does not exist (not created): every job is pending")
    client = store.connect(uri)
    exp = client.get_experiment_by_name(cfg.experiment)
    if exp is None or exp.lifecycle_stage == "deleted":
        return DryPlan(jobs, [], f"experiment '{cfg.experiment}' does not exist in {uri}: every job is pending")
    pending, done, _ = plan(client, str(exp.experiment_id), jobs)
    return DryPlan(pending, done, f"checked against experiment '{cfg.experiment}' in {uri}")


def run_sweep(cfg: RunConfig, reporter: SweepReporter) -> SweepSummary:
    """Validate, plan, train the pending jobs in ``cfg.workers`` processes, record the sweep."""
    start = time.perf_counter()
    cfg.validate()
    client = store.connect(cfg.tracking_uri)
    tracking_uri = store.resolve_tracking_uri(cfg.tracking_uri)
    vlm_label, simulated = vlm_identity(cfg)
    experiment_id = store.ensure_experiment(client, cfg.experiment)
    pending, done, stale = plan(client, experiment_id, cfg.jobs())
    summary = SweepSummary(None, experiment_id, skipped=[j.name for j in done])
    for run in stale:
        store.set_tags(client, run.info.run_id, {schema.TAG_ERROR: "left RUNNING by an interrupted sweep"})
        client.set_terminated(run.info.run_id, "FAILED")
        summary.marked_failed.append(run.info.run_id)
    reporter.planned(pending, done)
    if not pending:
        summary.wall_s = time.perf_counter() - start
        return summary

    parent = client.create_run(experiment_id, tags={
        **store.provenance_tags(vlm_label, simulated),
        schema.MLFLOW_RUN_NAME: f"sweep-{time.strftime('%Y%m%d-%H%M%S')}",
        schema.TAG_KIND: schema.KIND_SWEEP,
        schema.TAG_CONFIG_HASH: config_hash(cfg),
        **({schema.TAG_REGIME: cfg.regime} if cfg.regime is not None else {}),
    })
    summary.parent_run_id = parent.info.run_id
    store.log_params(client, parent.info.run_id, flatten(dataclasses.replace(cfg, ppo=cfg.ppo_config)))

    ctx = mp.get_context("spawn")
    events: Any = ctx.Queue()
    stop: Any = ctx.Event()
    status = "FINISHED"
    try:
        with _stop_on_sigint(stop) as interrupted, ProcessPoolExecutor(
            max_workers=min(cfg.workers, len(pending)), mp_context=ctx, initializer=init_worker,
            initargs=(events, stop),
        ) as pool:
            futures: dict[Future[JobResult], TrainJob] = {
                pool.submit(train_job, job, tracking_uri, experiment_id, parent.info.run_id, vlm_label,
                            simulated): job
                for job in pending
            }
            remaining = set(futures)
            while remaining:
                finished, remaining = wait(remaining, timeout=0.2, return_when=FIRST_COMPLETED)
                _drain(events, reporter)
                for fut in finished:
                    if fut.cancelled():
                        continue
                    result = fut.result()
                    summary.results.append(result)
                    reporter.finished(result)
                if interrupted.is_set() and status != "KILLED":
                    # queued jobs never start; running ones see `stop`, end their run KILLED and return
                    status = "KILLED"
                    for fut in remaining:
                        fut.cancel()
            _drain(events, reporter)
        if status == "KILLED":
            raise KeyboardInterrupt
        if summary.failed:
            status = "FAILED"
    except BaseException:
        status = status if status == "KILLED" else "FAILED"
        raise
    finally:
        summary.wall_s = time.perf_counter() - start
        store.log_params(client, parent.info.run_id, {"sweep.pending": ",".join(j.name for j in pending)})
        client.log_metric(parent.info.run_id, schema.METRIC_SWEEP_WALL_S, summary.wall_s)
        client.set_terminated(parent.info.run_id, status)
    return summary


@contextmanager
def _stop_on_sigint(stop: Any) -> Iterator[threading.Event]:
    """While the sweep runs, Ctrl-C sets a flag and the workers' stop event instead of raising
    KeyboardInterrupt inside ``concurrent.futures``, whose locks an asynchronous exception can
    leave held (the executor then never shuts down). A second Ctrl-C raises at once. The
    previous handler is restored on exit; off the main thread nothing is installed."""
    flag = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return

    def on_sigint(signum: int, frame: object) -> None:
        if flag.is_set():
            raise KeyboardInterrupt
        flag.set()
        stop.set()

    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        yield flag
    finally:
        signal.signal(signal.SIGINT, previous)


def _drain(events: Any, reporter: SweepReporter) -> None:
    while True:
        try:
            event = events.get_nowait()
        except (queue_mod.Empty, OSError, EOFError):
            return
        reporter.progress(event)
