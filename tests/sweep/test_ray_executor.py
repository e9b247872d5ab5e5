"""The Ray executor on a real local Ray instance (2 CPUs, loopback only): through a tracking
server, the numbers a local worker gives, and a worker killed mid-run is retried without a second
FINISHED run."""

from __future__ import annotations

import dataclasses
import os
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from mlflow.tracking import MlflowClient

from vlmrl_cli.sweep.ray_executor import start_local
from vlmrl_cli.sweep.runner import SilentReporter, run_sweep
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.tracking.store import connect
from vlmrl_cli.training.config import RunConfig
from vlmrl_cli.training.events import ProgressEvent
from vlmrl_cli.training.presets import preset_of
from vlmrl_cli.training.trace import native_returns

pytestmark = pytest.mark.slow  # trains, starts Ray or servers, or builds the wheel

ray = pytest.importorskip("ray")


class _Recording(SilentReporter):
    """Shows nothing; keeps the progress events."""

    def __init__(self) -> None:
        self.events: list[ProgressEvent] = []

    def progress(self, event: ProgressEvent) -> None:
        self.events.append(event)


@pytest.fixture(scope="module")
def local_ray() -> Iterator[None]:
    start_local(2)
    yield
    ray.shutdown()


def _histories(uri: str, experiment: str) -> dict[tuple[str, str], list[tuple[int, float, float]]]:
    client = MlflowClient(tracking_uri=uri)
    exp = client.get_experiment_by_name(experiment)
    assert exp is not None
    out = {}
    for run in client.search_runs([exp.experiment_id], "tags.`vlmrl.kind` = 'train'"):
        assert run.info.status == "FINISHED"
        key = (run.data.tags["vlmrl.arm"], run.data.tags["vlmrl.seed"])
        native = sorted(client.get_metric_history(run.info.run_id, "episode/native_return"),
                        key=lambda m: (m.step, m.timestamp))
        shaped = sorted(client.get_metric_history(run.info.run_id, "episode/shaped_return"),
                        key=lambda m: (m.step, m.timestamp))
        out[key] = [(n.step, n.value, s.value) for n, s in zip(native, shaped, strict=True)]
    return out


def test_a_killed_ray_worker_is_retried_and_finishes_once(tmp_path: Path, local_ray: None) -> None:
    uri = f"sqlite:///{tmp_path / 'm.db'}"
    # long enough that the first attempt cannot finish between two polls (the retry trains it whole)
    ppo = dataclasses.replace(preset_of(get_task("mountain-car"), "smoke"), timesteps=12_000)
    cfg = RunConfig(arms=("baseline",), seeds=(0,), preset="smoke", ppo=ppo, workers=2, tracking_uri=uri,
                    executor="ray", max_retries=2)
    # the store is set up (under vlmrl's lock, whole) before the sweep starts: a bare MlflowClient
    # would build its schema unlocked while the sweep checks the file, and the sweep refuses it
    client = connect(uri)
    box: dict[str, Any] = {}
    thread = threading.Thread(target=lambda: box.update(summary=run_sweep(cfg, SilentReporter())))
    thread.start()
    killed = None
    deadline = time.monotonic() + 240
    while killed is None and time.monotonic() < deadline and thread.is_alive():
        exp = client.get_experiment_by_name("vlmrl")
        runs = [] if exp is None else client.search_runs(
            [exp.experiment_id], "tags.`vlmrl.kind` = 'train' and attributes.status = 'RUNNING'")
        for run in runs:  # the job's run is open: its worker is building the env or training
            killed = run
            os.kill(int(run.data.tags["vlmrl.owner"].rsplit(":", 1)[1]), signal.SIGKILL)
        time.sleep(0.2)
    thread.join(timeout=600)
    assert killed is not None, "no training run to kill appeared"
    summary = box["summary"]
    assert len(summary.finished) == 1 and summary.failed == []
    assert summary.retried == [killed.info.run_id]
    exp = client.get_experiment_by_name("vlmrl")
    assert exp is not None
    runs = client.search_runs([exp.experiment_id], "tags.`vlmrl.kind` = 'train'")
    statuses = {r.info.run_id: r.info.status for r in runs}
    assert statuses[killed.info.run_id] == "FAILED"
    assert sorted(statuses.values()) == ["FAILED", "FINISHED"]
    assert "superseded" in client.get_run(killed.info.run_id).data.tags["vlmrl.error"]


def test_a_ray_sweep_through_a_loopback_tracking_server_trains_what_a_local_worker_does(
        tmp_path: Path, local_ray: None) -> None:
    """Workers write through ``mlflow server``; artifacts go up through it and come back; progress
    comes back from the Ray tasks; and every run's curve is the one the worker's own training path
    gives in this process (``training.trace``, which ``vlmrl verify`` holds the local pool's runs
    to: tests/cli/test_verify.py), so Ray trains what the local pool trains."""
    from tests.sweep.tracking_server import TrackingServer

    server = TrackingServer(tmp_path)
    server.start()
    try:
        cfg = RunConfig(arms=("baseline", "hybrid"), seeds=(0, 1), preset="smoke", workers=2,
                        tracking_uri=server.uri, executor="ray")
        reporter = _Recording()
        summary = run_sweep(cfg, reporter)
        assert len(summary.finished) == 4 and summary.failed == []
        assert reporter.events  # progress came back from the Ray tasks
        client = MlflowClient(tracking_uri=server.uri)
        assert client.get_run(str(summary.parent_run_id)).data.tags["vlmrl.executor"] == "ray"
        for result in summary.finished:
            names = {a.path for a in client.list_artifacts(result.run_id)}
            assert {"model.zip", "config.json"} <= names
        local = client.download_artifacts(summary.finished[0].run_id, "config.json", str(tmp_path))
        assert '"config_hash"' in Path(local).read_text()
        assert (tmp_path / "artifacts").exists()  # stored by the server, not by the workers
        histories = _histories(server.uri, cfg.experiment)
        assert set(histories) == {("baseline", "0"), ("baseline", "1"), ("hybrid", "0"), ("hybrid", "1")}
        for job in cfg.jobs():
            curve = [native for _, native, _ in histories[(job.arm.name, str(job.seed))]]
            assert curve and curve == native_returns(job), job.name
    finally:
        server.stop()
