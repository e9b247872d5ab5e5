"""OpenAIBackend against real HTTP servers on 127.0.0.1: request format, retries, failures."""

from __future__ import annotations

import base64
import io
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from tests.vlm.fake_openai import (
    CANNED,
    Body,
    FakeServer,
    Recorded,
    completion,
    down_url,
    fail_then,
    list_models,
    status_only,
)
from vlmrl_cli.core.errors import BackendUnavailable, BadInput
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.tasks.mountain_car.prompts import PROMPTS, Prompt, PromptKind
from vlmrl_cli.vlm.base import Backend
from vlmrl_cli.vlm.config import VLMConfig
from vlmrl_cli.vlm.openai_compat import OpenAIBackend
from vlmrl_cli.vlm.registry import build_backend

KEY_ENV = "VLMRL_TEST_API_KEY"
SECRET = "sk-test-0123456789abcdef"
CHAT = "/v1/chat/completions"
FAST_BACKOFF = 0.01


def cfg(base_url: str | None, model: str | None = "m", **kw: Any) -> VLMConfig:
    kw.setdefault("timeout_s", 2.0)
    kw.setdefault("retries", 2)
    return VLMConfig(backend="openai", model=model, base_url=base_url, api_key_env=KEY_ENV, cache_path=None, **kw)


def connect(base_url: str, **kw: Any) -> OpenAIBackend:
    return OpenAIBackend.from_config(cfg(base_url, **kw), backoff_s=FAST_BACKOFF)


def one_sentence(exc: pytest.ExceptionInfo[BaseException]) -> str:
    msg = str(exc.value)
    assert "\n" not in msg and msg.endswith(".") and "Traceback" not in msg
    assert SECRET not in msg
    return msg


@pytest.fixture(autouse=True)
def _no_key(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(KEY_ENV, raising=False)


# -- (a) the request on the wire --------------------------------------------------------------


@pytest.mark.parametrize("kind", list(PromptKind))
def test_request_carries_model_prompt_image_and_key(
    kind: PromptKind, frame: Frame, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(KEY_ENV, SECRET)
    with FakeServer() as server:
        backend = build_backend(cfg(server.url, max_new_tokens=17))  # the registry's code path
        assert isinstance(backend, OpenAIBackend) and isinstance(backend, Backend)
        assert (backend.name, backend.model, backend.simulated) == ("openai", "m", False)
        assert backend.answer(PROMPTS[kind], frame) == CANNED[kind]
        backend.close()
    assert [r.path for r in server.requests] == ["/v1/models", CHAT]
    request = server.on(CHAT)[0]
    body = request.json()
    assert body["model"] == "m"
    assert body["temperature"] == 0
    assert body["max_tokens"] == 17
    assert request.prompt_text == PROMPTS[kind].text
    assert request.headers["authorization"] == f"Bearer {SECRET}"
    assert server.requests[0].headers["authorization"] == f"Bearer {SECRET}"
    prefix = "data:image/png;base64,"
    assert request.image_url.startswith(prefix)
    png = base64.b64decode(request.image_url[len(prefix):])
    assert png.startswith(b"\x89PNG\r\n\x1a\n")
    np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(png)).convert("RGB")), frame.pixels)


def test_key_is_never_stored_or_shown(frame: Frame, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(KEY_ENV, SECRET)
    with FakeServer() as server:
        backend = connect(server.url)
        backend.answer(PROMPTS[PromptKind.MCQ], frame)
        assert SECRET not in repr(backend)
        assert SECRET not in str(vars(backend))
        assert server.url in repr(backend)
        backend.close()


def test_no_authorization_header_without_a_key(frame: Frame) -> None:
    with FakeServer() as server:
        backend = connect(server.url)
        backend.answer(PROMPTS[PromptKind.FLOAT], frame)
        backend.close()
    assert all("authorization" not in r.headers for r in server.requests)


def test_refused_key_is_not_echoed(frame: Frame, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(KEY_ENV, SECRET)
    echo = status_only(401, {"error": {"message": f"Incorrect API key provided: {SECRET}"}})
    with FakeServer(models=echo) as server, pytest.raises(BackendUnavailable) as exc:
        connect(server.url)
    msg = one_sentence(exc)
    assert "HTTP 401" in msg and KEY_ENV in msg
    assert len(server.requests) == 1  # 4xx is not retried
    with FakeServer(chat=echo) as server:
        backend = connect(server.url)
        with pytest.raises(BackendUnavailable) as exc:
            backend.answer(PROMPTS[PromptKind.FLOAT], frame)
        backend.close()
    assert "HTTP 401" in one_sentence(exc) and "***" in str(exc.value)


def test_missing_key_hint_names_the_variable() -> None:
    with FakeServer(models=status_only(401, {"error": "unauthorized"})) as server, \
            pytest.raises(BackendUnavailable, match=f"set the API key in the environment variable {KEY_ENV}"):
        connect(server.url)


def test_url_credentials_are_not_shown() -> None:
    with pytest.raises(BackendUnavailable) as exc:
        connect(down_url().replace("http://", "http://user:hunter2@"), retries=0)
    assert "hunter2" not in one_sentence(exc)
    backend = OpenAIBackend("http://user:hunter2@127.0.0.1:9/v1", "m")
    assert "hunter2" not in repr(backend)
    backend.close()


# -- (b) a server that is down, and retries -----------------------------------------------------


def test_down_server_is_unavailable_after_retries() -> None:
    start = time.perf_counter()
    with pytest.raises(BackendUnavailable) as exc:
        connect(down_url(), retries=2)
    msg = one_sentence(exc)
    assert "is unreachable" in msg and "3 attempt(s)" in msg and "--base-url" in msg
    assert time.perf_counter() - start < 2.0


def test_down_server_through_the_registry() -> None:
    with pytest.raises(BackendUnavailable, match=r"^the VLM server at http://127\.0\.0\.1:\d+/v1 is unreachable"):
        build_backend(cfg(down_url(), retries=0))


def test_503_twice_then_success(frame: Frame) -> None:
    with FakeServer(chat=fail_then(2, 503, lambda r, i: (200, completion("-0.5")))) as server:
        backend = connect(server.url, retries=2)
        assert backend.answer(PROMPTS[PromptKind.FLOAT], frame) == "-0.5"
        backend.close()
    assert len(server.on(CHAT)) == 3


def test_backoff_is_exponential(frame: Frame) -> None:
    with FakeServer(chat=fail_then(2, 502, lambda r, i: (200, completion("ok")))) as server:
        backend = OpenAIBackend.from_config(cfg(server.url, retries=2), backoff_s=0.1)
        start = time.perf_counter()
        assert backend.answer(PROMPTS[PromptKind.FLOAT], frame) == "ok"
        elapsed = time.perf_counter() - start
        backend.close()
    assert 0.3 <= elapsed < 1.5  # waits of 0.1 s then 0.2 s


def test_retries_exhausted_on_5xx(frame: Frame) -> None:
    with FakeServer(chat=status_only(503, {"error": "busy"})) as server:
        backend = connect(server.url, retries=2)
        with pytest.raises(BackendUnavailable) as exc:
            backend.answer(PROMPTS[PromptKind.FLOAT], frame)
        backend.close()
    assert "HTTP 503" in one_sentence(exc)
    assert len(server.on(CHAT)) == 3


def test_429_is_retried(frame: Frame) -> None:
    with FakeServer(chat=fail_then(1, 429, lambda r, i: (200, completion("x")))) as server:
        backend = connect(server.url, retries=1)
        assert backend.answer(PROMPTS[PromptKind.FLOAT], frame) == "x"
        backend.close()
    assert len(server.on(CHAT)) == 2


def test_timeout_counts_as_unreachable(frame: Frame) -> None:
    def slow(request: Recorded, index: int) -> tuple[int, Body]:
        time.sleep(1.0)
        return 200, completion("late")

    with FakeServer(chat=slow) as server:
        backend = connect(server.url, retries=1, timeout_s=0.2)
        with pytest.raises(BackendUnavailable) as exc:
            backend.answer(PROMPTS[PromptKind.FLOAT], frame)
        backend.close()
    assert "ReadTimeout" in one_sentence(exc) and "2 attempt(s)" in str(exc.value)


def test_model_not_found_is_not_retried_and_lists_served_models(frame: Frame) -> None:
    not_found = status_only(404, {"error": {"message": 'model "m" not found, try pulling it first'}})
    with FakeServer(chat=not_found, models=list_models("llava:7b", "qwen2.5vl")) as server:
        backend = connect(server.url)
        with pytest.raises(BackendUnavailable) as exc:
            backend.answer(PROMPTS[PromptKind.MCQ], frame)
        backend.close()
    msg = one_sentence(exc)
    assert "HTTP 404" in msg and "not found" in msg and "--model 'm'" in msg and "llava:7b" in msg
    assert len(server.on(CHAT)) == 1


# -- (c) malformed answers ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "body",
    ["this is not json {", "[1, 2, 3]", {"choices": []}, {"choices": [{"message": {"content": None}}]},
     {"choices": [{"text": "legacy completions format"}]}, {"error": "oops"}],
    ids=["not-json", "json-list", "no-choices", "null-content", "no-message", "error-object"],
)
def test_malformed_response(body: Body, frame: Frame) -> None:
    with FakeServer(chat=status_only(200, body)) as server:
        backend = connect(server.url)
        with pytest.raises(BackendUnavailable) as exc:
            backend.answer(PROMPTS[PromptKind.FLOAT], frame)
        backend.close()
    assert "returned a malformed response" in one_sentence(exc)
    assert len(server.on(CHAT)) == 1


def test_content_parts_are_joined(frame: Frame) -> None:
    parts = [{"type": "text", "text": "[1, 2, "}, {"type": "text", "text": "3, 4]"}]
    with FakeServer(chat=status_only(200, completion(parts))) as server:
        backend = connect(server.url)
        assert backend.answer(PROMPTS[PromptKind.BOX], frame) == "[1, 2, 3, 4]"
        backend.close()


# -- the reachability check and configuration ------------------------------------------------


@pytest.mark.parametrize("models", [status_only(404, "404 page not found"), status_only(405), status_only(500)])
def test_servers_without_models_route_still_work(models: Any, frame: Frame) -> None:
    with FakeServer(models=models) as server:
        backend = connect(server.url, retries=0)
        assert backend.answer(PROMPTS[PromptKind.MCQ], frame) == CANNED[PromptKind.MCQ]
        backend.close()


@pytest.mark.parametrize(
    ("base_url", "model", "match"),
    [(None, "m", "needs --base-url"), ("", "m", "needs --base-url"), ("localhost:11434/v1", "m", "http"),
     ("http://127.0.0.1:9/v1", None, "needs --model")],
)
def test_bad_configuration(base_url: str | None, model: str | None, match: str) -> None:
    with pytest.raises(BadInput, match=match) as exc:
        build_backend(cfg(base_url, model=model))
    assert "\n" not in str(exc.value)


def test_trailing_slash_in_base_url(frame: Frame) -> None:
    with FakeServer() as server:
        backend = connect(server.url + "/")
        backend.answer(PROMPTS[PromptKind.FLOAT], frame)
        backend.close()
    assert [r.path for r in server.requests] == ["/v1/models", CHAT]


# -- (d) the tiny HF model served over HTTP ---------------------------------------------------


@pytest.mark.usefixtures("single_thread_torch")
def test_tiny_hf_model_behind_http(tiny_llava_dir: Path, frame: Frame) -> None:
    from vlmrl_cli.vlm.hf import HFBackend

    hf = HFBackend.from_config(VLMConfig(backend="hf", model=str(tiny_llava_dir), device="cpu", cache_path=None))

    def serve_hf(request: Recorded, index: int) -> tuple[int, Body]:
        png = base64.b64decode(request.image_url.split(",", 1)[1])
        pixels = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
        text = hf.answer(Prompt(PromptKind.FLOAT, request.prompt_text), Frame.from_pixels(pixels))
        return 200, completion(text)

    with FakeServer(chat=serve_hf) as server:
        backend = connect(server.url)
        for kind in PromptKind:
            assert backend.answer(PROMPTS[kind], frame) == hf.answer(PROMPTS[kind], frame)
        backend.close()
    hf.close()
