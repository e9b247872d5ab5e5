"""Where a sweep's jobs run: a local process pool, or Ray tasks on a cluster; both only dispatch
the same job function. ``stop`` (Ctrl-C) ends running jobs KILLED and queued ones CANCELLED."""

from __future__ import annotations

import multiprocessing as mp
import os
import queue as queue_mod
import signal
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass
from importlib.util import find_spec
from typing import Any, Protocol

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.training.config import RunConfig, TrainJob
from vlmrl_cli.training.events import JobContext, JobResult, ProgressEvent

#: What an executor dispatches: one job, the sweep's shared context -> its result.
JobFn = Callable[[TrainJob, JobContext], JobResult]


#: What the local pool's fork server imports once before it forks any worker (about 5 s of CPU a
#: spawned worker spent on its own); none starts a thread on import, so forking it is safe.
PRELOAD: tuple[str, ...] = ("vlmrl_cli.sweep.worker", "mlflow.tracking", "mlflow.store.tracking.sqlalchemy_store")


def init_worker(progress: Any, stop: Any, environ: dict[str, str] | None = None) -> None:
    """The pool's initializer (``worker.init_worker``, imported in the worker: the sweep never loads
    torch); ``environ``: the sweep's environment, which a forked worker takes over."""
    if environ is not None:
        os.environ.clear()
        os.environ.update(environ)
    from vlmrl_cli.sweep.worker import init_worker as set_up

    set_up(progress, stop)


def train_job(job: TrainJob, ctx: JobContext) -> JobResult:
    """The default job (``worker.train_job``), imported in the worker."""
    from vlmrl_cli.sweep.worker import train_job as train

    return train(job, ctx)


@dataclass
class Polled:
    results: list[JobResult]
    events: list[ProgressEvent]


class Executor(Protocol):
    def submit(self, jobs: Sequence[TrainJob], job_fn: JobFn, ctx: JobContext) -> None: ...

    def poll(self, timeout_s: float) -> Polled: ...

    @property
    def outstanding(self) -> int: ...

    def stop(self) -> None: ...

    def close(self) -> None: ...


def check_executor(cfg: RunConfig) -> None:
    """``BadInput`` unless Ray is installed and, for a remote cluster, the store is a server."""
    if cfg.executor != "ray":
        return
    if is_remote_address(cfg.ray_address) and not is_server_uri(cfg.tracking_uri):
        raise BadInput(SHARED_STORE_NEEDED)
    if find_spec("ray") is None:
        raise BadInput("--executor ray needs Ray, which is not installed: pip install 'vlmrl[ray]'.")


SHARED_STORE_NEEDED = (
    "workers on other machines cannot write to a local sqlite or file store: start a tracking server "
    "(mlflow server --backend-store-uri sqlite:///PATH/mlflow.db --artifacts-destination PATH/artifacts "
    "--serve-artifacts --host 0.0.0.0 --port 5000) and pass --tracking-uri http://HOST:5000."
)


def is_server_uri(uri: str | None) -> bool:
    from vlmrl_cli.tracking.access import resolve_tracking_uri

    return resolve_tracking_uri(uri).startswith(("http://", "https://", "databricks"))


def is_remote_address(address: str | None) -> bool:
    """Whether a Ray address names another machine (``auto``, ``local`` and loopback do not)."""
    if address is None or address in ("auto", "local"):
        return False
    host = address.removeprefix("ray://").rsplit(":", 1)[0].strip("[]")
    return host not in ("127.0.0.1", "localhost", "::1", "0.0.0.0")


@contextmanager
def _sigint_blocked() -> Iterator[None]:
    """SIGINT held pending (not lost) in this thread, and in every process started meanwhile."""
    if not hasattr(signal, "pthread_sigmask"):  # not POSIX: nothing to block
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


class LocalExecutor:
    """A pool of ``workers`` processes (one torch thread each) forked from multiprocessing's fork
    server, which imported ``PRELOAD`` once: a worker costs a fork and shares no state with the sweep."""

    def __init__(self, workers: int) -> None:
        if "forkserver" in mp.get_all_start_methods():
            ctx: Any = mp.get_context("forkserver")
            ctx.set_forkserver_preload(list(PRELOAD))  # read when the fork server starts; later calls do nothing
        else:  # Windows has no fork server: spawned workers, each importing for itself
            ctx = mp.get_context("spawn")
        self._events: Any = ctx.Queue()
        self._stop: Any = ctx.Event()
        self._pool = ProcessPoolExecutor(max_workers=max(1, workers), mp_context=ctx, initializer=init_worker,
                                         initargs=(self._events, self._stop, dict(os.environ)))
        self._futures: dict[Future[JobResult], TrainJob] = {}
        self._lost = False

    @property
    def reusable(self) -> bool:
        """Whether another sweep may use this pool: no worker was lost (which breaks it) and no stop asked."""
        return not self._lost and not self._stop.is_set()

    def submit(self, jobs: Sequence[TrainJob], job_fn: JobFn, ctx: JobContext) -> None:
        # The pool (and the first time, the fork server) starts its processes here. A terminal's Ctrl-C
        # reaches the whole process group and would kill one still importing; started with SIGINT
        # blocked, they inherit the block, and the sweep gets the Ctrl-C once the block ends.
        with _sigint_blocked():
            for job in jobs:
                self._futures[self._pool.submit(job_fn, job, ctx)] = job

    def poll(self, timeout_s: float) -> Polled:
        finished, _ = wait(set(self._futures), timeout=timeout_s, return_when=FIRST_COMPLETED)
        results = []
        for fut in finished:
            job = self._futures.pop(fut)
            exc = fut.exception()  # no future is ever cancelled (``stop``)
            self._lost = self._lost or exc is not None
            results.append(fut.result() if exc is None else
                           JobResult(job.name, "", "FAILED", 0.0, error=f"worker process lost: {exc}"))
        return Polled(results, self._drain())

    @property
    def outstanding(self) -> int:
        return len(self._futures)

    def stop(self) -> None:
        # No future is cancelled: in CPython 3.11 a result for a future cancelled meanwhile raises
        # InvalidStateError in the pool's manager thread, which then hangs the sweep.
        self._stop.set()

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)

    def _drain(self) -> list[ProgressEvent]:
        events = []
        while True:
            try:
                events.append(self._events.get_nowait())
            except (queue_mod.Empty, OSError, EOFError):
                return events
