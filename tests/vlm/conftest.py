"""Fixtures of the VLM backend tests: a tiny offline LLaVA, a rendered frame, hub offline mode."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.vlm.tiny_llava import build_tiny_llava
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer


@pytest.fixture(scope="session")
def tiny_llava_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny random LLaVA saved like a downloaded model (built once per session, ~200 kB)."""
    return build_tiny_llava(tmp_path_factory.mktemp("tiny-llava"))


@pytest.fixture(scope="session")
def sighted_llava_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny LLaVA with its projector scaled up (``image_gain``): its answers differ by frame."""
    return build_tiny_llava(tmp_path_factory.mktemp("sighted-llava"), image_gain=30.0)


@pytest.fixture(scope="session")
def frames() -> Iterator[list[Frame]]:
    """Nine MountainCar frames along the track, left to right."""
    with FrameRenderer() as renderer:
        yield [renderer.render(x, frame_id=f"x={x:.2f}") for x in (-1.1, -0.9, -0.7, -0.5, -0.3, -0.1, 0.1, 0.3, 0.5)]


@pytest.fixture(scope="session")
def frame() -> Iterator[Frame]:
    """A real MountainCar frame, car in the valley."""
    with FrameRenderer() as renderer:
        yield renderer.render(-0.5, frame_id="x=-0.50")


@pytest.fixture
def hub_offline(monkeypatch: pytest.MonkeyPatch) -> None:
    """Hugging Face hub offline mode for one test, so hub ids fail at once instead of after
    minutes of network retries. huggingface_hub reads ``HF_HUB_OFFLINE`` at import, so the
    constant is patched as well as the variable."""
    import huggingface_hub.constants

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setattr(huggingface_hub.constants, "HF_HUB_OFFLINE", True)


@pytest.fixture(scope="module")
def single_thread_torch() -> Iterator[None]:
    """One intra-op torch thread while a module's tests run (restored after): the tiny model's
    ops are so small that thread hand-offs dominate, ~0.4 s per answer on 2 threads vs ~35 ms."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
