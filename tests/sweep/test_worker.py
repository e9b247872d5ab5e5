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
