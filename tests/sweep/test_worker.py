"""The sweep worker's process set-up (``init_worker``, the pool's initializer)."""

from __future__ import annotations

import os

import pytest
import torch

from vlmrl_cli.sweep import worker


def test_a_worker_chooses_a_headless_video_driver_unless_its_process_has_one(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(worker, "_channels", worker.Channels())  # init_worker fills the module's channels
    threads = torch.get_num_threads()
    try:
        monkeypatch.delenv("SDL_VIDEODRIVER", raising=False)
        worker.init_worker(None, None, ignore_sigint=False)
        assert os.environ["SDL_VIDEODRIVER"] == "dummy"
        monkeypatch.setenv("SDL_VIDEODRIVER", "offscreen")
        worker.init_worker(None, None, ignore_sigint=False)
        assert os.environ["SDL_VIDEODRIVER"] == "offscreen"
    finally:
        torch.set_num_threads(threads)  # init_worker pins torch to one thread: this process is no worker


def test_a_shaped_run_records_its_scales_and_where_they_came_from() -> None:
    from vlmrl_cli.sweep.worker import run_tags
    from vlmrl_cli.tracking import schema
    from vlmrl_cli.training.config import RunConfig

    def tags(task: str, sets: list[str], arm: str = "hybrid") -> dict[str, str]:
        flags = {"arms": [arm], "seeds": [0], "preset": "smoke", "task": task}
        job = RunConfig.from_sources(None, flags, sets).jobs()[0]
        return run_tags(job, None, "sim", True)

    assert tags("mountain-car", [])[schema.TAG_SCALES] == "alpha 5, kin_scale 2 (the paper's)"
    own = tags("minigrid-doorkey", [])[schema.TAG_SCALES]
    assert own.startswith("alpha 0.241, kin_scale 0.172 (the task's rule: ")
    assert tags("minigrid-doorkey", ["shaping.alpha=5"])[schema.TAG_SCALES].endswith("(set for this run)")
    assert schema.TAG_SCALES not in tags("acrobot", [], arm="baseline")
