"""HFBackend against a tiny random LLaVA built offline: the same load path as a hub model."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import torch

from tests.mountain_car_helpers import parse_box, parse_float, parse_mcq
from tests.vlm.tiny_llava import folder_size_bytes
from vlmrl_cli.core.errors import BackendUnavailable, BadInput
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.tasks.mountain_car.prompts import PROMPTS
from vlmrl_cli.vlm.base import Backend
from vlmrl_cli.vlm.config import VLMConfig
from vlmrl_cli.vlm.hf import HFBackend, _looks_like_path, resolve_dtype
from vlmrl_cli.vlm.parsers import ParseStatus
from vlmrl_cli.vlm.prompts import PromptKind
from vlmrl_cli.vlm.registry import build_backend

pytestmark = pytest.mark.usefixtures("single_thread_torch")

PARSERS: dict[PromptKind, Callable[[str], Any]] = {
    PromptKind.FLOAT: parse_float, PromptKind.BOX: parse_box, PromptKind.MCQ: parse_mcq,
}


def hf_config(model: str | Path | None, **kw: Any) -> VLMConfig:
    return VLMConfig(backend="hf", model=None if model is None else str(model), device="cpu", cache_path=None, **kw)


@pytest.fixture(scope="module")
def tiny_backend(tiny_llava_dir: Path) -> Any:
    backend = build_backend(hf_config(tiny_llava_dir))
    yield backend
    backend.close()


def test_tiny_model_is_tiny(tiny_llava_dir: Path) -> None:
    assert (tiny_llava_dir / "config.json").is_file()
    assert folder_size_bytes(tiny_llava_dir) < 2_000_000


def test_loads_through_the_registry_like_a_user_model(tiny_backend: Any, tiny_llava_dir: Path) -> None:
    assert isinstance(tiny_backend, HFBackend)
    assert isinstance(tiny_backend, Backend)
    assert (tiny_backend.name, tiny_backend.simulated) == ("hf", False)
    assert tiny_backend.model == str(tiny_llava_dir)
    assert "cpu" in repr(tiny_backend)


@pytest.mark.parametrize("kind", list(PromptKind))
def test_answers_every_prompt_and_parsers_classify_the_garbage(
    tiny_backend: Any, frame: Frame, kind: PromptKind
) -> None:
    start = time.perf_counter()
    text = tiny_backend.answer(PROMPTS[kind], frame)
    elapsed = time.perf_counter() - start
    assert isinstance(text, str)
    assert PROMPTS[kind].text not in text  # only the new tokens are decoded
    assert elapsed < 2.0  # ~35 ms on one CPU thread
    result = PARSERS[kind](text)  # random weights: garbage, but a parser never raises
    assert isinstance(result.status, ParseStatus)


def test_greedy_answers_are_deterministic(tiny_backend: Any, frame: Frame) -> None:
    prompt = PROMPTS[PromptKind.MCQ]
    assert tiny_backend.answer(prompt, frame) == tiny_backend.answer(prompt, frame)


def test_decodes_only_the_new_tokens(tiny_llava_dir: Path, frame: Frame, monkeypatch: pytest.MonkeyPatch) -> None:
    backend = HFBackend.from_config(hf_config(tiny_llava_dir))
    loaded = backend._loaded
    assert loaded is not None
    answer_ids = loaded.processor.tokenizer("BOTTOM", add_special_tokens=False, return_tensors="pt")["input_ids"]

    def generate(input_ids: torch.Tensor, **kwargs: Any) -> torch.Tensor:
        assert kwargs["do_sample"] is False and kwargs["max_new_tokens"] == 32
        assert "pixel_values" in kwargs
        return torch.cat([input_ids, answer_ids], dim=1)

    monkeypatch.setattr(loaded.model, "generate", generate)
    assert backend.answer(PROMPTS[PromptKind.MCQ], frame) == "BOTTOM"


def test_generation_error_gives_an_empty_answer(
    tiny_llava_dir: Path, frame: Frame, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    backend = HFBackend.from_config(hf_config(tiny_llava_dir))
    assert backend._loaded is not None

    def broken(**kwargs: Any) -> torch.Tensor:
        raise RuntimeError("index out of range in self")

    monkeypatch.setattr(backend._loaded.model, "generate", broken)
    with caplog.at_level(logging.WARNING, logger="vlmrl_cli.vlm.hf"):
        assert backend.answer(PROMPTS[PromptKind.FLOAT], frame) == ""
    assert "index out of range" in caplog.text
    assert parse_float("").status is ParseStatus.EMPTY


def test_closed_backend_refuses(tiny_llava_dir: Path, frame: Frame) -> None:
    backend = HFBackend.from_config(hf_config(tiny_llava_dir))
    backend.close()
    with pytest.raises(BackendUnavailable, match="closed"):
        backend.answer(PROMPTS[PromptKind.FLOAT], frame)


def assert_one_sentence(exc: pytest.ExceptionInfo[BaseException]) -> str:
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.endswith(".")
    assert "Traceback" not in msg
    return msg


def test_missing_model_path(tmp_path: Path) -> None:
    missing = tmp_path / "no-such-model"
    with pytest.raises(BackendUnavailable) as exc:
        build_backend(hf_config(missing))
    msg = assert_one_sentence(exc)
    assert str(missing) in msg and "no such local folder" in msg and "--model" in msg


def test_nonexistent_absolute_path_fails_fast() -> None:
    start = time.perf_counter()
    with pytest.raises(BackendUnavailable, match="no such local folder"):
        HFBackend.from_config(hf_config("/nonexistent"))
    assert time.perf_counter() - start < 1.0


def test_folder_without_config(tmp_path: Path) -> None:
    with pytest.raises(BackendUnavailable) as exc:
        HFBackend.from_config(hf_config(tmp_path))
    assert "config.json" in assert_one_sentence(exc)


def test_missing_model_option() -> None:
    with pytest.raises(BackendUnavailable) as exc:
        HFBackend.from_config(hf_config(None))
    assert "--model" in assert_one_sentence(exc)


@pytest.mark.usefixtures("hub_offline")
def test_unknown_hub_id_while_offline() -> None:
    start = time.perf_counter()
    with pytest.raises(BackendUnavailable) as exc:
        HFBackend.from_config(hf_config("nobody-here/no-such-vlm"))
    msg = assert_one_sentence(exc)
    assert msg.startswith("cannot load the model 'nobody-here/no-such-vlm' with transformers")
    assert "unreachable" in msg and "--model PATH" in msg
    assert time.perf_counter() - start < 5.0


def test_folder_that_is_not_a_vlm(tmp_path: Path) -> None:
    (tmp_path / "config.json").write_text('{"model_type": "no-such-architecture"}')
    with pytest.raises(BackendUnavailable) as exc:
        HFBackend.from_config(hf_config(tmp_path))
    assert assert_one_sentence(exc).startswith(f"cannot load the model '{tmp_path}'")


def test_unknown_dtype(tiny_llava_dir: Path) -> None:
    with pytest.raises(BadInput, match="--dtype"):
        HFBackend.from_config(hf_config(tiny_llava_dir, dtype="float8"))


@pytest.mark.parametrize(
    ("name", "device", "expected"),
    [("auto", "cpu", torch.float32), ("auto", "cuda", torch.float16), ("auto", "cuda:1", torch.float16),
     ("bfloat16", "cpu", torch.bfloat16), ("float32", "cuda", torch.float32)],
)
def test_resolve_dtype(name: str, device: str, expected: torch.dtype) -> None:
    assert resolve_dtype(name, device) is expected


@pytest.mark.parametrize(
    ("model", "is_path"),
    [("llava-hf/llava-1.5-7b-hf", False), ("gpt2", False), ("/nonexistent", True), ("./models/llava", True),
     ("~/models/llava", True), ("models/llava/v1", True), ("C:\\models\\llava", True)],
)
def test_path_or_hub_id(model: str, is_path: bool) -> None:
    assert _looks_like_path(model) is is_path
