"""VLM throughput figures for ``docs/real-vlm.md`` (issue 53: a real VLM at the speed of PPO). Prints measurements.

  1. the tiny random LLaVA built offline (tests/vlm/tiny_llava.py), on this CPU with one torch
     thread: ``--frames`` MountainCar frames asked the MCQ one at a time (``answer``), as one round
     (``answer_many``: batched ``generate``) and scored by option log-probability (``score_many``:
     one prefill and one continuation pass). The model is tiny (~43k parameters), so the figures
     show the batching overhead saved, not a 7B model's speed.
  2. the loopback OpenAI-compatible test server (tests/vlm/fake_openai.py) answering after a fixed
     ``--latency`` per request: the same frames with 1, 4, 8 and 16 requests in flight.

Usage: python benchmarks/bench_vlm.py [--frames 16] [--latency 0.2] [--repeats 3]
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout: the tests' tiny LLaVA and server

from vlmrl_cli.core.numeric_pin import apply as pin_numeric_path

pin_numeric_path()  # before torch and numpy load

import argparse
import tempfile
import time
from collections.abc import Callable

from tests.vlm.fake_openai import FakeServer, mcq_by_image
from tests.vlm.tiny_llava import build_tiny_llava
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.tasks.mountain_car.prompts import ZONE_MILESTONES
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer
from vlmrl_cli.vlm.config import VLMConfig
from vlmrl_cli.vlm.hf import HFBackend
from vlmrl_cli.vlm.openai_compat import OpenAIBackend

MCQ = ZONE_MILESTONES.prompt


def best_of(repeats: int, work: Callable[[], object]) -> float:
    """The fastest of ``repeats`` timings of ``work``, in seconds."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        work()
        times.append(time.perf_counter() - start)
    return min(times)


def bench_hf(frames: list[Frame], repeats: int) -> None:
    import torch

    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        folder = build_tiny_llava(Path(tmp) / "llava", image_gain=30.0)
        backend = HFBackend.from_config(VLMConfig(backend="hf", model=str(folder), device="cpu", cache_path=None,
                                                  max_concurrency=len(frames)))
        serial_answers = [backend.answer(MCQ, f) for f in frames]
        assert backend.answer_many(MCQ, frames) == serial_answers, "batched answers differ from serial ones"
        rows = [("serial generate (answer x n)", best_of(repeats, lambda: [backend.answer(MCQ, f) for f in frames])),
                (f"batched generate (answer_many, batch {len(frames)})",
                 best_of(repeats, lambda: backend.answer_many(MCQ, frames))),
                (f"option log-probabilities (score_many, batch {len(frames)})",
                 best_of(repeats, lambda: backend.score_many(MCQ, frames)))]
        backend.close()
    print(f"tiny LLaVA on CPU, 1 torch thread, {len(frames)} frames, max_new_tokens 32:")
    for name, seconds in rows:
        print(f"  {name:<48} {seconds:7.3f} s  {len(frames) / seconds:8.1f} frames/s  "
              f"{rows[0][1] / seconds:5.1f}x serial")


def bench_openai(frames: list[Frame], latency: float) -> None:
    print(f"loopback OpenAI-compatible server, {latency * 1000:.0f} ms per request, {len(frames)} frames:")
    with FakeServer(chat=mcq_by_image(ZONE_MILESTONES.labels, latency_s=latency)) as server:
        base = None
        for concurrency in (1, 4, 8, 16):
            cfg = VLMConfig(backend="openai", model="m", base_url=server.url, cache_path=None, retries=0,
                            max_concurrency=concurrency)
            backend = OpenAIBackend.from_config(cfg)
            try:
                start = time.perf_counter()
                answers = backend.answer_many(MCQ, frames)
                seconds = time.perf_counter() - start
            finally:
                backend.close()
            base = base or (answers, seconds)
            assert answers == base[0], "concurrent answers differ from serial ones"
            print(f"  {concurrency:>2} in flight  {seconds:6.2f} s  {len(frames) / seconds:6.1f} queries/s  "
                  f"{base[1] / seconds:5.1f}x one in flight")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--frames", type=int, default=16)
    parser.add_argument("--latency", type=float, default=0.2)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with FrameRenderer() as renderer:
        step = 1.7 / max(1, args.frames - 1)
        frames = [renderer.render(-1.2 + i * step, frame_id=f"f{i}") for i in range(args.frames)]
    bench_hf(frames, args.repeats)
    bench_openai(frames, args.latency)


if __name__ == "__main__":
    main()
