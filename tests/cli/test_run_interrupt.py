"""Ctrl-C during `vlmrl run`: a clean stop (exit 130, runs KILLED), and the rerun redoes them.

The signal goes to the whole process group, as a terminal sends it. A SIGINT to the sweep's own
process alone takes the same path (its handler stops the executor; a worker ignores SIGINT
either way), so it has no test of its own: one launch per moment and executor."""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import time
from importlib.util import find_spec
from pathlib import Path

import pytest

from vlmrl_cli.sweep.runner import plan
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.tracking import store
from vlmrl_cli.training.config import RunConfig
from vlmrl_cli.training.presets import preset_of

pytestmark = pytest.mark.slow  # trains, starts Ray or servers, or builds the wheel


def _runs(uri: str) -> list:  # type: ignore[type-arg]
    # through vlmrl's own connect: it takes the store's init lock, so this poll cannot race the
    # sweep's first connection to the new database (an unlocked MlflowClient here once broke it)
    client = store.connect(uri)
    exp = client.get_experiment_by_name("vlmrl")
    return [] if exp is None else list(client.search_runs([exp.experiment_id]))


EXECUTORS = [
    pytest.param([], id="local"),
    pytest.param(["--executor", "ray", "--ray-address", "local"], id="ray",
                 marks=pytest.mark.skipif(find_spec("ray") is None, reason="Ray is not installed")),
]


def _started(uri: str) -> bool:  # the parent run exists: workers are being spawned and import torch
    return any(r.data.tags.get("vlmrl.kind") == "sweep" for r in _runs(uri))


def _training(uri: str) -> bool:  # a worker's first episodes reached MLflow
    return any(r.data.tags.get("vlmrl.kind") == "train" and r.data.metrics.get("episode/native_return")
               for r in _runs(uri))


def _shutting_down(uri: str) -> bool:  # the last training run ended: the sweep is closing down
    runs = [r for r in _runs(uri) if r.data.tags.get("vlmrl.kind") == "train"]
    return len(runs) == 2 and all(r.info.status != "RUNNING" for r in runs)


@pytest.mark.parametrize("executor", EXECUTORS)
@pytest.mark.parametrize(("moment", "timesteps"), [
    ("start-up", 200_000), ("training", 200_000), ("shutdown", 1_024),
])
def test_ctrl_c_to_the_whole_group_at_any_moment_stops_at_once(tmp_path: Path, executor: list[str], moment: str,
                                                               timesteps: int) -> None:
    """A terminal's Ctrl-C reaches every process of the group (workers still importing torch, or
    a worker training, or the sweep closing its parent run): one signal stops it within seconds,
    with exit 130 (or 0 when the sweep had already finished), no traceback and no run left RUNNING."""
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    # two local workers where both are still starting; one where it trains or has finished (the other
    # job waits in the queue, or ran after it), and one Ray worker throughout (a Ray worker is a
    # fresh interpreter that imports torch, about 6 core-seconds): the same handling at less CPU
    workers = "2" if moment == "start-up" and not executor else "1"
    args = [sys.executable, "-m", "vlmrl_cli", "run", "--arms", "baseline,hybrid", "--seeds", "1", "--preset", "smoke",
            "--workers", workers, "--tracking-uri", uri, "--timesteps", str(timesteps), *executor]
    ready = {"start-up": _started, "training": _training, "shutdown": _shutting_down}[moment]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
                            env={**os.environ, "COLUMNS": "120"})
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and proc.poll() is None:
            if (tmp_path / "mlflow.db").exists() and ready(uri):
                break
            # each poll opens the store: often only where the moment is short (the shutdown's)
            time.sleep(0.1 if moment == "shutdown" else 0.3)
        else:
            if proc.poll() is None:
                raise AssertionError(f"the sweep never reached the moment '{moment}'")
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)
        sent = time.monotonic()
        _, stderr = proc.communicate(timeout=90)
        took = time.monotonic() - sent
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    expected = (130, 0) if moment == "shutdown" else (130,)
    assert proc.returncode in expected, stderr[-3000:]
    assert "Traceback" not in stderr and "InvalidStateError" not in stderr, stderr[-3000:]
    assert took < 60, took
    statuses = [(r.data.tags["vlmrl.kind"], r.info.status) for r in _runs(uri)]
    assert all(status != "RUNNING" for _, status in statuses), statuses
    if moment != "shutdown":  # at shutdown the parent may have closed FINISHED just before the signal
        assert ("sweep", "KILLED") in statuses, statuses
        assert "interrupted" in stderr, stderr[-3000:]
    if moment == "training":
        # a worker was training: its run ended KILLED (the other job, if it had not started, has no run)
        assert set(statuses) == {("sweep", "KILLED"), ("train", "KILLED")}, statuses
        # and every job is pending again: rerunning the same command trains them
        ppo = dataclasses.replace(preset_of(get_task("mountain-car"), "smoke"), timesteps=timesteps)
        cfg = RunConfig(arms=("baseline", "hybrid"), seeds=(0,), preset="smoke", ppo=ppo, tracking_uri=uri)
        client = store.connect(uri)
        exp = client.get_experiment_by_name("vlmrl")
        assert exp is not None
        found = plan(client, exp.experiment_id, cfg.jobs())
        assert sorted(j.name for j in found.pending) == ["baseline-s0", "hybrid-s0"], found
        assert found.done == [] and found.elsewhere == []
