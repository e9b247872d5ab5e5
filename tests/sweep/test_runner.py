"""The sweep runner's lifecycle: a Ctrl-C at any point after the parent run exists closes it KILLED."""

from __future__ import annotations

import os
import signal
from pathlib import Path
from typing import Any

import pytest

from vlmrl_cli.sweep import runner
from vlmrl_cli.sweep.runner import SilentReporter, run_sweep
from vlmrl_cli.sweep.worker import JobContext
from vlmrl_cli.tracking import store
from vlmrl_cli.training.config import RunConfig, TrainJob


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
