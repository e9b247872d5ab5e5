"""The sweep runner's lifecycle: a Ctrl-C at any point after the parent run exists closes it KILLED;
successive sweeps of one command share a local pool, which a lost worker retires."""

from __future__ import annotations

import os
import signal
from pathlib import Path
from typing import Any

import pytest

from vlmrl_cli.sweep import runner
from vlmrl_cli.sweep.runner import SharedPool, SilentReporter, run_sweep
from vlmrl_cli.sweep.worker import JobContext
from vlmrl_cli.tracking import store
from vlmrl_cli.training.config import RunConfig, TrainJob
from vlmrl_cli.training.events import JobResult


def _never(job: TrainJob, ctx: JobContext) -> Any:  # what a job would run: must not be reached
    raise AssertionError("a job was submitted after the Ctrl-C")


def test_ctrl_c_while_the_parent_logs_its_params_closes_it_killed(tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The window CI once hit: the parent run exists (a poller sees it) but its params are still
    being written. The signal must mark the parent KILLED, submit nothing, and end in
    KeyboardInterrupt (exit 130 at the CLI), not leave the parent RUNNING."""
    uri = f"sqlite:///{tmp_path / 'm.db'}"
    original = store.log_params
    calls = {"n": 0}

    def log_params_then_ctrl_c(*args: Any, **kwargs: Any) -> None:
        calls["n"] += 1
        if calls["n"] == 1:
            os.kill(os.getpid(), signal.SIGINT)  # delivered in the middle of the parent's start-up
        original(*args, **kwargs)

    monkeypatch.setattr(runner.store, "log_params", log_params_then_ctrl_c)
    before = signal.getsignal(signal.SIGINT)  # pytest-xdist's workers ignore SIGINT; a plain run has the default
    cfg = RunConfig(arms=("baseline",), seeds=(0,), preset="smoke", workers=1, tracking_uri=uri)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(cfg, SilentReporter(), job_fn=_never)
    monkeypatch.undo()
    client = store.connect(uri)
    exp = client.get_experiment_by_name(cfg.experiment)
    assert exp is not None
    runs = client.search_runs([exp.experiment_id])
    assert [(r.data.tags["vlmrl.kind"], r.info.status) for r in runs] == [("sweep", "KILLED")]
    assert signal.getsignal(signal.SIGINT) == before  # the previous handler was restored


def _pid_job(job: TrainJob, ctx: JobContext) -> JobResult:  # reports the worker process that ran it
    return JobResult(job.name, str(os.getpid()), "FINISHED", 0.0)


def _lost_job(job: TrainJob, ctx: JobContext) -> JobResult:  # the worker dies, as an out-of-memory kill would
    os._exit(3)


def test_successive_sweeps_share_one_pool_until_a_worker_is_lost(tmp_path: Path) -> None:
    uri = f"sqlite:///{tmp_path / 'm.db'}"
    cfg = RunConfig(arms=("baseline",), seeds=(0,), preset="smoke", workers=1, tracking_uri=uri)
    with SharedPool() as pool:
        first = run_sweep(cfg, SilentReporter(), job_fn=_pid_job, pool=pool)
        second = run_sweep(cfg, SilentReporter(), job_fn=_pid_job, pool=pool)
        assert [r.run_id for r in first.results] == [r.run_id for r in second.results]  # one worker process
        lost = run_sweep(cfg, SilentReporter(), job_fn=_lost_job, pool=pool)
        assert [r.status for r in lost.results] == ["FAILED"] and "worker process lost" in str(lost.results[0].error)
        after = run_sweep(cfg, SilentReporter(), job_fn=_pid_job, pool=pool)  # a fresh pool, not the broken one
        assert [r.status for r in after.results] == ["FINISHED"]
        assert after.results[0].run_id != first.results[0].run_id
    alone = run_sweep(cfg, SilentReporter(), job_fn=_pid_job)  # without a pool, a sweep starts its own
    assert alone.results[0].run_id not in (first.results[0].run_id, after.results[0].run_id)
