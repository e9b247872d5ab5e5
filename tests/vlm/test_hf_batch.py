"""HFBackend's batched answers and option log-probabilities against the tiny LLaVA built offline:
a batch says what one-by-one answers say, and the scores are a direct forward pass's."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import torch

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.tasks.mountain_car.prompts import PROMPTS
from vlmrl_cli.vlm.base import ScoringBackend, answer_all
from vlmrl_cli.vlm.client import VLMClient
from vlmrl_cli.vlm.config import VLMConfig
from vlmrl_cli.vlm.hf import HFBackend
from vlmrl_cli.vlm.prompts import PromptKind
from vlmrl_cli.vlm.sim import SimulatedVLM
from vlmrl_cli.vlm.transcript import read_transcript

pytestmark = pytest.mark.usefixtures("single_thread_torch")
MCQ = PROMPTS[PromptKind.MCQ]


@pytest.fixture(scope="module")
def sighted(sighted_llava_dir: Path) -> Iterator[HFBackend]:
    backend = HFBackend.from_config(VLMConfig(backend="hf", model=str(sighted_llava_dir), device="cpu",
                                              cache_path=None))
    yield backend
    backend.close()


@pytest.mark.parametrize("kind", list(PromptKind))
def test_batched_and_serial_answers_are_identical(sighted: HFBackend, frames: list[Frame], kind: PromptKind) -> None:
    serial = [sighted.answer(PROMPTS[kind], f) for f in frames]
    assert len(frames) >= 8
    assert sighted.answer_many(PROMPTS[kind], frames) == serial
    assert answer_all(sighted, PROMPTS[kind], frames) == serial


def test_the_answers_differ_by_frame_so_a_misplaced_answer_shows(sighted: HFBackend, frames: list[Frame]) -> None:
    serial = [sighted.answer(MCQ, f) for f in frames]
    assert len(set(serial)) > 1
    assert sighted.answer_many(MCQ, frames[::-1]) == serial[::-1]


def test_batches_of_any_size_answer_alike(sighted: HFBackend, frames: list[Frame],
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    whole = sighted.answer_many(MCQ, frames)
    monkeypatch.setattr(sighted, "batch_size", 2)
    assert sighted.answer_many(MCQ, frames) == whole


def test_a_failing_batch_is_asked_frame_by_frame(sighted: HFBackend, frames: list[Frame],
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    serial = [sighted.answer(MCQ, f) for f in frames[:3]]
    real = sighted._generate

    def fails_on_batches(loaded: Any, prompt: Any, chunk: Any) -> list[str]:
        if len(chunk) > 1:
            raise RuntimeError("out of memory")
        return real(loaded, prompt, chunk)

    monkeypatch.setattr(sighted, "_generate", fails_on_batches)
    assert sighted.answer_many(MCQ, frames[:3]) == serial


def reference_logprob(backend: HFBackend, frame: Frame, option: str) -> float:
    """log p(option | prompt, image) from one plain forward pass over prompt + answer, by hand."""
    from PIL import Image

    loaded = backend._loaded
    assert loaded is not None
    processor, model = loaded.processor, loaded.model
    chat = processor.apply_chat_template(
        [{"role": "user", "content": [{"type": "image"}, {"type": "text", "text": MCQ.text}]}],
        add_generation_prompt=True, tokenize=False)
    image = Image.fromarray(frame.pixels)
    prefix = processor(images=[image], text=[chat], return_tensors="pt")["input_ids"]
    full = processor(images=[image], text=[chat + " " + option], return_tensors="pt")
    ids = full["input_ids"][0]
    assert torch.equal(ids[:prefix.shape[1]], prefix[0])  # the answer's tokens follow the prompt's
    with torch.no_grad():
        logits = model(**full).logits[0]
    logp = torch.log_softmax(logits.float(), dim=-1)
    return float(sum(logp[t - 1, ids[t]] for t in range(prefix.shape[1], len(ids))))


def test_option_logprobs_agree_with_a_direct_forward_pass(sighted: HFBackend, frames: list[Frame]) -> None:
    assert MCQ.options is not None
    assert max(len(t) for t in sighted.option_ids(MCQ)) > 1  # the continuation pass is exercised
    some = [frames[0], frames[4], frames[8]]
    scores = sighted.score_many(MCQ, some)
    for frame, got in zip(some, scores, strict=True):
        assert got is not None and got.options == MCQ.options
        want = [reference_logprob(sighted, frame, option) for option in MCQ.options]
        assert got.logprobs == pytest.approx(want, abs=1e-4)
        assert got.label == MCQ.options[max(range(len(want)), key=want.__getitem__)]
        assert got.margin == pytest.approx(sorted(want)[-1] - sorted(want)[-2], abs=1e-4)


def test_scores_do_not_depend_on_the_batch(sighted: HFBackend, frames: list[Frame],
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    whole = sighted.score_many(MCQ, frames)
    monkeypatch.setattr(sighted, "batch_size", 1)
    alone = sighted.score_many(MCQ, frames)
    for a, b in zip(whole, alone, strict=True):
        assert a is not None and b is not None
        assert a.label == b.label and a.logprobs == pytest.approx(b.logprobs, abs=1e-4)


def test_the_client_scores_an_mcq_and_records_its_confidence(sighted: HFBackend, frames: list[Frame],
                                                              tmp_path: Path) -> None:
    assert isinstance(sighted, ScoringBackend)
    client = VLMClient(sighted, transcript=tmp_path / "t.jsonl")
    answers = client.ask_many(MCQ, frames[:4])
    scores = sighted.score_many(MCQ, frames[:4])
    assert [a.text for a in answers] == [s.label for s in scores if s is not None]
    assert all(a.confidence is not None and a.confidence >= 0 for a in answers)
    assert client.stats.scored == 4 and client.stats.generated == 0
    assert "MCQ by option log-probability" in client.label
    client.ask(PROMPTS[PromptKind.FLOAT], frames[0])  # a float question is still generated
    assert client.stats.generated == 1
    client.transcript.close()  # type: ignore[union-attr]
    records = read_transcript(tmp_path / "t.jsonl")
    assert [r.confidence for r in records[:4]] == pytest.approx([a.confidence for a in answers])
    assert "confidence" not in json.loads((tmp_path / "t.jsonl").read_text().splitlines()[-1])


def test_generate_mode_decodes_and_says_so(sighted: HFBackend, frames: list[Frame]) -> None:
    client = VLMClient(sighted, mcq_mode="generate")
    answers = client.ask_many(MCQ, frames[:3])
    assert [a.text for a in answers] == [sighted.answer(MCQ, f) for f in frames[:3]]
    assert all(a.confidence is None for a in answers)
    assert client.stats.scored == 0 and "MCQ by generation" in client.label


def test_logprob_mode_refuses_a_backend_that_cannot_score() -> None:
    class Text:
        name, model, simulated = "text", "t", False

        def answer(self, prompt: Any, frame: Any) -> str:
            return ""

        def close(self) -> None:
            pass

    with pytest.raises(BadInput, match="mcq_mode=logprob needs a backend that scores options"):
        VLMClient(Text(), mcq_mode="logprob")  # type: ignore[arg-type]
    assert not hasattr(SimulatedVLM, "score_many")  # the simulated VLM keeps generating
