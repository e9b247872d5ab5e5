"""``VLMClient.ask_many``: one backend call per round, answers that do not depend on the split,
the transcript in the order asked, the cache and the stochastic case."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from vlmrl_cli.frames.render import Frame
from vlmrl_cli.vlm.cache import ResponseCache
from vlmrl_cli.vlm.client import VLMClient
from vlmrl_cli.vlm.prompts import mcq_prompt

MCQ_PROMPT = mcq_prompt("A scene.", ("A", "B"))


def _frames(values: Sequence[int]) -> list[Frame]:
    return [Frame.from_pixels(np.full((4, 4, 3), v, dtype=np.uint8), frame_id=f"v={v}") for v in values]


class Counting:
    """A deterministic backend that answers each frame's first pixel, counting its calls; with
    ``batch`` it answers a list in one call."""

    name, model, simulated = "count", "c", True

    def __init__(self, stochastic: bool = False) -> None:
        self.calls: list[int] = []
        self.stochastic = stochastic
        self.draws = 0

    def answer(self, prompt: object, frame: Frame) -> str:
        self.calls.append(1)
        self.draws += 1
        return f"{int(frame.pixels[0, 0, 0])}" + (f"#{self.draws}" if self.stochastic else "")

    def close(self) -> None:
        pass


class Batching(Counting):
    def answer_many(self, prompt: object, frames: Sequence[Frame]) -> list[str]:
        self.calls.append(len(frames))
        out = []
        for frame in frames:
            self.draws += 1
            out.append(f"{int(frame.pixels[0, 0, 0])}" + (f"#{self.draws}" if self.stochastic else ""))
        return out


def _transcript(path: Path) -> list[tuple[str, bool]]:
    return [(r["answer"], r["cached"]) for r in map(json.loads, path.read_text().splitlines())]


def test_a_round_is_one_backend_call_and_the_split_changes_no_answer(tmp_path: Path) -> None:
    frames = _frames([3, 1, 3, 2, 1])
    one, two = Batching(), Batching()
    batched = VLMClient(one, ResponseCache(tmp_path / "a.sqlite"), transcript=tmp_path / "a.jsonl")
    serial = VLMClient(two, ResponseCache(tmp_path / "b.sqlite"), transcript=tmp_path / "b.jsonl")
    together = [a.text for a in batched.ask_many(MCQ_PROMPT, frames)]
    one_by_one = [serial.ask(MCQ_PROMPT, f).text for f in frames]
    assert together == one_by_one == ["3", "1", "3", "2", "1"]
    assert one.calls == [3]  # one call, each distinct frame once
    assert two.calls == [1, 1, 1]
    batched.close()
    serial.close()
    # the transcript lists every query in the order asked, and a repeat as the cache hit it is
    assert _transcript(tmp_path / "a.jsonl") == _transcript(tmp_path / "b.jsonl") == [
        ("3", False), ("1", False), ("3", True), ("2", False), ("1", True)]
    assert (batched.stats.queries, batched.stats.cache_hits, batched.stats.backend_frames) == (5, 2, 3)
    assert batched.stats.largest_batch == 3 and batched.stats.backend_calls == 1


def test_a_backend_without_batches_is_asked_frame_by_frame_in_order(tmp_path: Path) -> None:
    backend = Counting()
    client = VLMClient(backend, None)
    assert [a.text for a in client.ask_many(MCQ_PROMPT, _frames([5, 6, 5]))] == ["5", "6", "5"]
    assert backend.calls == [1, 1]
    assert client.ask_many(MCQ_PROMPT, []) == []


def test_a_stochastic_backend_draws_once_per_query_in_order(tmp_path: Path) -> None:
    frames = _frames([1, 1, 2])
    batched = VLMClient(Batching(stochastic=True), ResponseCache(tmp_path / "c.sqlite"))
    serial = VLMClient(Batching(stochastic=True), ResponseCache(tmp_path / "d.sqlite"))
    assert batched.cache is None  # a fresh draw each time: nothing is cached
    assert [a.text for a in batched.ask_many(MCQ_PROMPT, frames)] == [serial.ask(MCQ_PROMPT, f).text for f in frames]
    assert [a.text for a in batched.ask_many(MCQ_PROMPT, frames)] == ["1#4", "1#5", "2#6"]
