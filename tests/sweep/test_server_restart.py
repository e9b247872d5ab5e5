"""A tracking server that goes away mid-sweep and comes back: the run finishes, no episode lost."""

from __future__ import annotations

import dataclasses
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from mlflow.tracking import MlflowClient

from tests.sweep.tracking_server import TrackingServer
from vlmrl_cli.sweep.runner import SilentReporter, run_sweep
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.training.config import RunConfig
from vlmrl_cli.training.presets import preset_of

pytestmark = pytest.mark.slow  # trains, starts Ray or servers, or builds the wheel

STEPS = 24_000  # about 12 s of training on two cores shared with another test
OUTAGE_S = 10.0


def test_the_server_stopped_and_restarted_mid_sweep(tmp_path: Path) -> None:
    server = TrackingServer(tmp_path)
    server.start()
    ppo = dataclasses.replace(preset_of(get_task("mountain-car"), "smoke"), timesteps=STEPS)
    cfg = RunConfig(arms=("baseline",), seeds=(0,), preset="smoke", ppo=ppo, workers=1, tracking_uri=server.uri)
    box: dict[str, Any] = {}
    thread = threading.Thread(target=lambda: box.update(summary=run_sweep(cfg, SilentReporter())))
    try:
        thread.start()
        client = MlflowClient(tracking_uri=server.uri)
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline:  # until the first episodes are on the server
            exp = client.get_experiment_by_name("vlmrl")
            runs = [] if exp is None else client.search_runs([exp.experiment_id], "tags.`vlmrl.kind` = 'train'")
            if any("episode/native_return" in r.data.metrics for r in runs):
                break
            time.sleep(0.5)
        else:
            raise AssertionError("no episode reached the server")
        server.stop()
        down = time.monotonic()
        # unreachable for 10 s (and while it restarts): two of the logger's 5-s writes fail, the worker
        # trains on and buffers
        time.sleep(OUTAGE_S)
        server.start()
        assert time.monotonic() - down >= OUTAGE_S
        assert thread.is_alive(), "the sweep ended while the server was down"
        thread.join(timeout=600)
        assert not thread.is_alive()
        summary = box["summary"]
        assert [r.status for r in summary.results] == ["FINISHED"]
        client = MlflowClient(tracking_uri=server.uri)
        run_id = summary.results[0].run_id
        lengths = client.get_metric_history(run_id, "episode/length")
        steps = sorted(m.step for m in lengths)
        # every episode is there: their lengths add up to the steps of all finished episodes
        # (the two envs' unfinished tails, under 200 steps each, are the only gap)
        assert len(steps) == len(set((m.step, m.timestamp) for m in lengths))
        total = sum(m.value for m in lengths)
        assert STEPS - 2 * 200 < total <= STEPS
        assert client.get_run(run_id).info.status == "FINISHED"
    finally:
        server.stop()
