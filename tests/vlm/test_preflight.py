"""check_vlm and check_coverage refuse what would fail later, creating nothing."""

from __future__ import annotations

from pathlib import Path

import pytest

from vlmrl_cli.core.errors import BackendUnavailable, BadInput
from vlmrl_cli.tasks.mountain_car.prompts import PROMPTS
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer
from vlmrl_cli.vlm.config import VLMConfig
from vlmrl_cli.vlm.preflight import check_coverage, check_vlm
from vlmrl_cli.vlm.prompts import PromptKind
from vlmrl_cli.vlm.transcript import TranscriptRecord, TranscriptWriter


def test_the_default_config_passes_and_creates_no_cache(tmp_path: Path) -> None:
    check_vlm(VLMConfig(cache_path=tmp_path / "sub" / "c.sqlite"))
    assert list(tmp_path.iterdir()) == []


def test_a_cache_path_under_a_file_is_refused(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    with pytest.raises(BadInput, match="response cache"):
        check_vlm(VLMConfig(cache_path=tmp_path / "f" / "c.sqlite"))


def test_an_hf_model_that_is_not_here_is_refused_without_loading(tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(BackendUnavailable, match="no such local folder"):
        check_vlm(VLMConfig(backend="hf", model=str(tmp_path / "none"), use_cache=False))
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setenv("HF_HOME", str(tmp_path / "hf"))
    with pytest.raises(BackendUnavailable, match="not in the local Hugging Face cache"):
        check_vlm(VLMConfig(backend="hf", model="someone/not-cached-model", use_cache=False))


def test_an_unknown_backend_is_refused() -> None:
    with pytest.raises(BadInput, match="unknown VLM backend"):
        check_vlm(VLMConfig(backend="nonsense", use_cache=False))


def test_coverage_counts_the_frames_a_transcript_cannot_answer(tmp_path: Path) -> None:
    with FrameRenderer() as renderer:
        frames = [renderer.render(x) for x in (-0.5, 0.0, 0.3)]
    path = tmp_path / "t.jsonl"
    writer = TranscriptWriter(path)
    writer.write(TranscriptRecord(backend="sim", model="m", prompt_kind="mcq", prompt="p",
                                  image_sha256=frames[0].sha256, answer="BOTTOM", latency_s=0.0, simulated=True,
                                  cached=False, frame_id=None))
    writer.close()
    cfg = VLMConfig(backend="replay", transcript_in=path, use_cache=False)
    check_coverage(cfg, [PROMPTS[PromptKind.MCQ]], frames[:1])  # covered
    with pytest.raises(BadInput, match="cannot answer 2 of the 3"):
        check_coverage(cfg, [PROMPTS[PromptKind.MCQ]], frames)
    check_coverage(VLMConfig(use_cache=False), [PROMPTS[PromptKind.MCQ]], frames)  # the simulated VLM answers anything
