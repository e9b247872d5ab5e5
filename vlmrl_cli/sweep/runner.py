"""Run every (arm, seed) job of a ``RunConfig`` through an executor, resumably and beside other
sweeps on the same store (``leases``; see docs/commands/run.md); one parent run per invocation."""

from __future__ import annotations

import dataclasses
import signal
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from vlmrl_cli.core.provenance import config_hash, flatten
from vlmrl_cli.shaping.arms import ARMS
from vlmrl_cli.sweep.executors import Executor, JobFn, LocalExecutor, train_job
from vlmrl_cli.sweep.leases import ACTIVE, Liveness, RunRecord, is_stale, mark_stale
from vlmrl_cli.sweep.preflight import preflight
from vlmrl_cli.tracking import schema, store
from vlmrl_cli.tracking.lifecycle import RunStatus, tracked_run
from vlmrl_cli.training.config import RunConfig, TrainJob
from vlmrl_cli.training.events import JobContext, JobResult, ProgressEvent, SweepSummary


class SweepReporter(Protocol):
    """What the sweep tells its caller (the CLI draws it with rich)."""

    def planned(self, pending: list[TrainJob], done: list[TrainJob]) -> None: ...

    def progress(self, event: ProgressEvent) -> None: ...

    def finished(self, result: JobResult) -> None: ...


class SilentReporter:
    """A ``SweepReporter`` that shows nothing (scripts, benchmarks, tests)."""

    def planned(self, pending: list[TrainJob], done: list[TrainJob]) -> None:
        pass

    def progress(self, event: ProgressEvent) -> None:
        pass

    def finished(self, result: JobResult) -> None:
        pass


def vlm_identity(cfg: RunConfig) -> tuple[str, bool]:
    """The sweep's VLM label and simulated flag, starting the backend once (``BadInput`` before
    anything trains); an hf model is not loaded here (``preflight`` has found its files)."""
    if not any(ARMS[name].uses_vlm for name in cfg.arms):
        return "none (no arm uses a VLM)", False
    if cfg.vlm.backend == "hf":
        return f"hf:{cfg.vlm.model or ''}", False
    from vlmrl_cli.vlm.base import describe
    from vlmrl_cli.vlm.registry import build_backend

    backend = build_backend(cfg.vlm, reader=cfg.task_plugin.reader)
    try:
        return describe(backend), bool(backend.simulated)
    finally:
        backend.close()


@dataclass(frozen=True)
class Plan:
    pending: list[TrainJob]  # to train here
    done: list[TrainJob]  # a FINISHED run exists
    stale: list[Any] = field(default_factory=list)  # RUNNING runs of pending jobs whose process is gone
    elsewhere: list[TrainJob] = field(default_factory=list)  # a live run of another sweep trains it
    note: str = ""  # a dry plan's: where the answer came from (or why every job is pending)
    experiment_id: str | None = None  # a dry plan's: the experiment checked, when it exists


def plan(client: Any, experiment_id: str, jobs: list[TrainJob], stale_after_s: float = 300.0) -> Plan:
    """Split jobs into pending, done and owned elsewhere, with the stale runs of pending jobs."""
    by_key = schema.train_runs_by_job(client, experiment_id)
    result = Plan([], [], [], [])
    live = Liveness.here(stale_after_s)
    for job in jobs:
        runs = by_key.get((job.arm.name, str(job.seed), job.config_hash), [])
        if any(r.info.status == "FINISHED" for r in runs):
            result.done.append(job)
            continue
        active = [r for r in runs if r.info.status in ACTIVE]
        stale = [r for r in active if is_stale(RunRecord.of(r), live)]
        if len(stale) < len(active):
            result.elsewhere.append(job)
        else:
            result.pending.append(job)
            result.stale.extend(stale)
    return result


def dry_plan(cfg: RunConfig) -> Plan:
    """Plan ``cfg``'s jobs against the store without writing anything (no store, experiment or mark)."""
    uri = store.resolve_tracking_uri(cfg.tracking_uri)
    jobs = cfg.jobs()
    if uri.startswith("sqlite:///") and not Path(uri.removeprefix("sqlite:///")).exists():
        return Plan(jobs, [], note=f"the tracking store {uri} does not exist (not created): every job is pending")
    client = store.connect(uri)
    exp = client.get_experiment_by_name(cfg.experiment)
    if exp is None or exp.lifecycle_stage == "deleted":
        return Plan(jobs, [], note=f"experiment '{cfg.experiment}' does not exist in {uri}: every job is pending")
    found = plan(client, str(exp.experiment_id), jobs, cfg.stale_after_s)
    return dataclasses.replace(found, note=f"checked against experiment '{cfg.experiment}' in {uri}",
                               experiment_id=str(exp.experiment_id))


class SharedPool:
    """One local process pool lent to the successive sweeps of one command (its workers import torch
    and MLflow once), replaced when it lost a worker, was stopped or has another size; a Ray sweep
    gets its own executor. A context manager: the pool closes when the command ends."""

    def __init__(self) -> None:
        self._local: LocalExecutor | None = None
        self._workers = 0

    def executor(self, cfg: RunConfig) -> Executor:
        if cfg.executor == "ray":
            from vlmrl_cli.sweep.ray_executor import RayExecutor

            return RayExecutor(cfg.ray_address, cfg.workers, cfg.max_retries, cfg.tracking_uri)
        if self._local is None or self._workers != cfg.workers or not self._local.reusable:
            self.close()
            # a pool starts a process per job up to its size: a sweep of fewer jobs starts fewer
            self._local, self._workers = LocalExecutor(cfg.workers), cfg.workers
        return self._local

    def release(self, executor: Executor) -> None:
        """The sweep is done with ``executor``: closed unless it is the shared pool."""
        if executor is not self._local:
            executor.close()

    def close(self) -> None:
        if self._local is not None:
            self._local.close()
            self._local = None

    def __enter__(self) -> SharedPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def run_sweep(cfg: RunConfig, reporter: SweepReporter, job_fn: JobFn = train_job,
              checked: bool = False, pool: SharedPool | None = None) -> SweepSummary:
    """Check, plan and train the pending jobs, recording the sweep; ``checked``: the caller has run
    ``preflight(cfg)``; ``pool``: a ``SharedPool`` lending the local executor."""
    start = time.perf_counter()
    if not checked:
        preflight(cfg)
    client = store.connect(cfg.tracking_uri)
    tracking_uri = store.resolve_tracking_uri(cfg.tracking_uri)
    vlm_label, simulated = vlm_identity(cfg)
    experiment_id = store.ensure_experiment(client, cfg.experiment)
    found = plan(client, experiment_id, cfg.jobs(), cfg.stale_after_s)
    pending, done = found.pending, found.done
    summary = SweepSummary(None, experiment_id, skipped=[j.name for j in done],
                           elsewhere=[j.name for j in found.elsewhere], executor=cfg.executor)
    for run in found.stale:
        mark_stale(client, run.info.run_id, "left RUNNING by an interrupted sweep (its process is gone or its "
                                            "heartbeat stale)")
        summary.marked_failed.append(run.info.run_id)
    reporter.planned(pending, done)
    if not pending:
        summary.wall_s = time.perf_counter() - start
        return summary
    executor = (pool or SharedPool()).executor(cfg)  # before the parent run: Ray may refuse the store
    release = pool.release if pool is not None else (lambda ex: ex.close())
    # The Ctrl-C flag covers the parent's creation to its close, so that no Ctrl-C leaves it RUNNING.
    with _stop_on_sigint() as interrupted:
        try:
            tags = {**store.provenance_tags(vlm_label, simulated), schema.TAG_KIND: schema.KIND_SWEEP,
                    schema.MLFLOW_RUN_NAME: f"sweep-{time.strftime('%Y%m%d-%H%M%S')}",
                    schema.TAG_CONFIG_HASH: config_hash(cfg), schema.TAG_EXECUTOR: cfg.executor,
                    schema.TAG_TASK: cfg.task, **({schema.TAG_REGIME: cfg.regime} if cfg.regime is not None else {})}
            parent = client.create_run(experiment_id, tags=tags)
        except BaseException:
            release(executor)
            raise
        summary.parent_run_id = parent.info.run_id
        with tracked_run(client, parent.info.run_id) as run:
            try:
                store.log_params(client, run.run_id, flatten(dataclasses.replace(cfg, ppo=cfg.ppo_config)))
                ctx = JobContext(tracking_uri, experiment_id, run.run_id, vlm_label, simulated,
                                 heartbeat_s=cfg.heartbeat_s, stale_after_s=cfg.stale_after_s)
                if not interrupted.is_set():  # a Ctrl-C during start-up: nothing is submitted
                    executor.submit(pending, job_fn, ctx)
                _follow(executor, reporter, summary, run, interrupted)
                if summary.failed and run.status != RunStatus.KILLED:
                    run.status = RunStatus.FAILED
            finally:
                release(executor)
                summary.wall_s = time.perf_counter() - start
                store.log_params(client, run.run_id, {"sweep.pending": ",".join(j.name for j in pending)})
                client.log_metric(run.run_id, schema.METRIC_SWEEP_WALL_S, summary.wall_s)
                if interrupted.is_set():
                    run.status = RunStatus.KILLED
    if run.status == RunStatus.KILLED:
        raise KeyboardInterrupt
    return summary


def _follow(executor: Executor, reporter: SweepReporter, summary: SweepSummary, run: Any,
            interrupted: threading.Event) -> None:
    """Report progress and results until no job is outstanding; on a Ctrl-C stop, and mark ``run`` KILLED."""
    while executor.outstanding:
        polled = executor.poll(0.2)
        for event in polled.events:
            reporter.progress(event)
        for result in polled.results:
            summary.results.append(result)
            reporter.finished(result)
        if interrupted.is_set() and run.status != RunStatus.KILLED:
            run.status = RunStatus.KILLED
            executor.stop()


@contextmanager
def _stop_on_sigint() -> Iterator[threading.Event]:
    """A flag that Ctrl-C sets (a second one raises) instead of raising inside ``concurrent.futures``
    or Ray, whose locks it could leave held; main thread only."""
    flag = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return

    def on_sigint(signum: int, frame: object) -> None:
        if flag.is_set():
            raise KeyboardInterrupt
        flag.set()

    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        yield flag
    finally:
        signal.signal(signal.SIGINT, previous)
