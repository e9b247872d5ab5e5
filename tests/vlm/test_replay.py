"""Replaying the paper's Table 1 transcript, and any transcript by frame hash or id."""

from __future__ import annotations

from pathlib import Path

import pytest

from vlmrl_cli.core.errors import BadInput, MissingAnswer
from vlmrl_cli.tasks.mountain_car.prompts import PROMPTS
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer
from vlmrl_cli.vlm.config import PAPER_MODEL, PAPER_TRANSCRIPT, VLMConfig
from vlmrl_cli.vlm.prompts import PromptKind
from vlmrl_cli.vlm.replay import ReplayBackend
from vlmrl_cli.vlm.transcript import TranscriptRecord, read_transcript

PAPER = {
    "x=-0.50": {"float": "0.378", "box": "Error [0, 0, 0, 0]", "mcq": "BOTTOM"},
    "x=-0.69": {"float": "0.386", "box": "Box [450, 210, 480, 230]", "mcq": "BOTTOM"},
}


@pytest.fixture(scope="module")
def renderer():
    with FrameRenderer() as r:
        yield r


def test_paper_transcript_is_consistent(renderer: FrameRenderer) -> None:
    records = read_transcript(PAPER_TRANSCRIPT)
    assert len(records) == 6
    for r in records:
        assert r.backend == "paper" and r.model == PAPER_MODEL and r.simulated is False
        assert r.latency_s == 0 and r.note and "paper" in r.note
        assert r.prompt == PROMPTS[PromptKind(r.prompt_kind)].text
        assert r.frame_id is not None
        assert r.answer == PAPER[r.frame_id][r.prompt_kind]
        x = float(r.frame_id.removeprefix("x="))
        assert r.image_sha256 == renderer.render(x).sha256  # our renderer still draws the same bytes


def test_replays_the_paper_by_image_hash(renderer: FrameRenderer) -> None:
    backend = ReplayBackend.from_config(VLMConfig(backend="replay"))
    assert backend.name == "replay" and backend.model == PAPER_MODEL and backend.simulated is False
    assert backend.frame_ids() == ["x=-0.50", "x=-0.69"]
    for frame_id, answers in PAPER.items():
        frame = renderer.render(float(frame_id.removeprefix("x=")))  # no id: the hash must match
        for kind in PromptKind:
            assert backend.answer(PROMPTS[kind], frame) == answers[kind.value]


def test_falls_back_to_frame_id_and_raises_missing_answer(renderer: FrameRenderer) -> None:
    backend = ReplayBackend.from_config(VLMConfig(backend="replay"))
    other = renderer.render(-0.3, frame_id="x=-0.50")
    assert backend.answer(PROMPTS[PromptKind.MCQ], other) == "BOTTOM"
    with pytest.raises(MissingAnswer):
        backend.answer(PROMPTS[PromptKind.MCQ], renderer.render(-0.3, frame_id="x=-0.30"))


def test_simulated_flag_follows_the_records() -> None:
    rec = TranscriptRecord(backend="sim", model="m", prompt_kind="mcq", prompt="p", image_sha256="h",
                           answer="BOTTOM", latency_s=0.0, simulated=True)
    assert ReplayBackend([rec]).simulated is True


@pytest.mark.parametrize("content", [None, "not json\n", "[1, 2]\n", ""])
def test_unreadable_transcripts_are_bad_input(tmp_path: Path, content: str | None) -> None:
    path = tmp_path / "t.jsonl"
    if content is not None:
        path.write_text(content)
    with pytest.raises(BadInput):
        ReplayBackend.from_config(VLMConfig(backend="replay", transcript_in=path))
