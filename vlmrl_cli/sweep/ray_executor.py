"""The Ray executor (``--executor ray``, the extra ``vlmrl[ray]``): each job a Ray task
(``num_cpus=1``) running the local pool's job function; progress through a Ray queue, Ctrl-C
through a flag actor the tasks poll. See docs/cluster.md."""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Sequence
from typing import Any

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.core.numeric_pin import PIN_VARIABLES, pinned_environ
from vlmrl_cli.sweep.executors import SHARED_STORE_NEEDED, JobFn, Polled, is_server_uri
from vlmrl_cli.sweep.worker import init_worker
from vlmrl_cli.training.config import TrainJob
from vlmrl_cli.training.events import JobContext, JobResult, ProgressEvent, StopFlag

POLL_STOP_S = 1.0


class _RemoteFlag:
    """``is_set()`` of the flag actor, copied into a local event by a thread every ``POLL_STOP_S`` seconds."""

    def __init__(self, actor: Any) -> None:
        import ray

        self._local = threading.Event()
        self._closed = threading.Event()

        def poll() -> None:
            while not self._closed.wait(POLL_STOP_S):
                with contextlib.suppress(Exception):  # the driver is gone or busy: keep training, ask again
                    if ray.get(actor.is_set.remote(), timeout=10):
                        self._local.set()
                        return

        threading.Thread(target=poll, name="vlmrl-stop-poll", daemon=True).start()

    def is_set(self) -> bool:
        return self._local.is_set()

    def close(self) -> None:
        self._closed.set()


class _QueueSink:
    def __init__(self, queue: Any) -> None:
        self._queue = queue

    def put(self, event: ProgressEvent) -> None:
        with contextlib.suppress(Exception):  # progress is best effort; training goes on
            self._queue.put_nowait(event)


def ray_job(job_fn: JobFn, job: TrainJob, ctx: JobContext, progress: Any, stop: Any) -> JobResult:
    """The body of every Ray task: set the worker up as the local pool does, run the job."""
    flag = _RemoteFlag(stop)
    init_worker(_QueueSink(progress), flag, ignore_sigint=False)
    try:
        return job_fn(job, ctx)
    finally:
        flag.close()


def init_options() -> dict[str, Any]:
    """``ray.init``'s options: no dashboard, workers' output kept off the progress display, and every
    worker on the driver's numeric pin."""
    import os

    pinned = pinned_environ(os.environ)
    return {"include_dashboard": False, "log_to_driver": False, "logging_level": logging.WARNING,
            "runtime_env": {"env_vars": {k: pinned[k] for k in PIN_VARIABLES}}}


def start_local(num_cpus: int) -> None:
    """Start a local Ray instance whose workers run at the driver's priority (Ray's niceness 15
    starved them: importing torch took 27 s beside a 2-worker sweep, against 1.9 s)."""
    import ray

    ray.init(num_cpus=num_cpus, _system_config={"worker_niceness": 0}, **init_options())


def connect(address: str | None, workers: int, tracking_uri: str | None) -> None:
    """Join ``address``, else a cluster on this machine (Ray's ``auto``), else start one with
    ``workers`` CPUs; a cluster of several machines needs a tracking server."""
    import ray

    if not ray.is_initialized() and address != "local":
        try:
            ray.init(address=address or "auto", **init_options())
        except (ConnectionError, RuntimeError) as exc:
            if address is not None:
                raise BadInput(f"cannot join the Ray cluster at '{address}': {exc}") from exc
    if not ray.is_initialized():
        start_local(workers)
    alive = [n for n in ray.nodes() if n.get("Alive")]
    if len(alive) > 1 and not is_server_uri(tracking_uri):
        raise BadInput(SHARED_STORE_NEEDED)


class RayExecutor:
    def __init__(self, address: str | None, workers: int, max_retries: int, tracking_uri: str | None) -> None:
        import ray
        from ray.util.queue import Queue

        connect(address, workers, tracking_uri)
        self._ray = ray
        self._max_retries = max_retries
        self._queue = Queue(actor_options={"num_cpus": 0})
        flag_actor: Any = ray.remote(num_cpus=0)(StopFlag)
        self._flag = flag_actor.remote()
        self._refs: dict[Any, TrainJob] = {}

    def submit(self, jobs: Sequence[TrainJob], job_fn: JobFn, ctx: JobContext) -> None:
        task = self._ray.remote(ray_job).options(num_cpus=1, max_retries=self._max_retries, retry_exceptions=False)
        for job in jobs:
            self._refs[task.remote(job_fn, job, ctx, self._queue, self._flag)] = job

    def poll(self, timeout_s: float) -> Polled:
        results: list[JobResult] = []
        if self._refs:
            ready, _ = self._ray.wait(list(self._refs), num_returns=len(self._refs), timeout=timeout_s)
            for ref in ready:
                job = self._refs.pop(ref)
                try:
                    results.append(self._ray.get(ref))
                except self._ray.exceptions.RayError as exc:
                    lost = isinstance(exc, (self._ray.exceptions.WorkerCrashedError,
                                            self._ray.exceptions.NodeDiedError))
                    why = f"its worker was lost {self._max_retries + 1} time(s)" if lost else "Ray could not run it"
                    results.append(JobResult(job.name, "", "FAILED", 0.0,
                                             error=f"{why}: {type(exc).__name__}: {exc}"[:2000]))
        return Polled(results, self._drain())

    @property
    def outstanding(self) -> int:
        return len(self._refs)

    def stop(self) -> None:
        self._ray.get(self._flag.set.remote())

    def close(self) -> None:
        actors: list[Any] = [self._queue.actor, self._flag]
        for actor in actors:
            with contextlib.suppress(Exception):  # already gone with a shut-down cluster
                self._ray.kill(actor)

    def _drain(self) -> list[ProgressEvent]:
        try:
            n = self._queue.qsize()
            return list(self._queue.get_nowait_batch(n)) if n else []
        except Exception:  # progress is best effort
            return []
