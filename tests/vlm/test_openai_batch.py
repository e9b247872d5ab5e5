"""OpenAIBackend's rounds of frames: concurrent requests to a loopback server that answers after a
fixed latency, in the order asked, and MCQs scored from the server's log-probabilities."""

from __future__ import annotations

import logging
import time
from contextlib import closing
from typing import Any

import pytest

from tests.vlm.fake_openai import FakeServer, completion, fail_then, image_label, mcq_by_image, status_only
from vlmrl_cli.core.errors import BackendUnavailable, BadInput
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.tasks.mountain_car.prompts import PROMPTS
from vlmrl_cli.vlm.client import VLMClient
from vlmrl_cli.vlm.config import VLMConfig
from vlmrl_cli.vlm.openai_compat import OpenAIBackend, image_data_url
from vlmrl_cli.vlm.prompts import PromptKind

MCQ = PROMPTS[PromptKind.MCQ]
LABELS = MCQ.options or ()
CHAT = "/v1/chat/completions"
LATENCY_S = 0.3  # per request; the client's own work per frame (PNG, base64, JSON) is ~10-30 ms under load


def connect(url: str, **kw: Any) -> OpenAIBackend:
    kw.setdefault("timeout_s", 5.0)
    kw.setdefault("retries", 0)
    cfg = VLMConfig(backend="openai", model="m", base_url=url, cache_path=None, **kw)
    return OpenAIBackend.from_config(cfg, backoff_s=0.01)


def timed_labels(url: str, frames: list[Frame], concurrency: int, mode: str, tries: int = 1
                 ) -> tuple[list[str], float]:
    """The labels of one round and its fastest wall time over ``tries`` (no cache: each asks the server)."""
    client = VLMClient(connect(url, max_concurrency=concurrency), mcq_mode=mode)
    try:
        best, labels = float("inf"), []
        for _ in range(tries):
            start = time.perf_counter()
            labels = [a.text for a in client.ask_many(MCQ, frames)]
            best = min(best, time.perf_counter() - start)
        return labels, best
    finally:
        client.close()


@pytest.mark.parametrize("mode", ["generate", "logprob"])
def test_eight_requests_in_flight_are_four_times_faster_and_answer_alike(frames: list[Frame], mode: str) -> None:
    eight = frames[:8]
    with FakeServer(chat=mcq_by_image(LABELS, latency_s=LATENCY_S)) as server:
        serial, serial_s = timed_labels(server.url, eight, 1, mode)
        concurrent, concurrent_s = timed_labels(server.url, eight, 8, mode, tries=2)  # a busy machine's hiccup
        asked = [r.json() for r in server.on(CHAT)]
    speedup = serial_s / concurrent_s
    print(f"\n{mode}: 8 frames at {LATENCY_S * 1000:.0f} ms each: 1 in flight {serial_s:.2f} s, "
          f"8 in flight {concurrent_s:.2f} s: {speedup:.1f}x")
    assert concurrent == serial
    assert len(set(serial)) > 1  # the frames' labels differ: an answer out of place would show
    assert speedup >= 4.0
    assert all(bool(body.get("logprobs")) is (mode == "logprob") for body in asked)


def test_answers_come_back_in_the_order_asked(frames: list[Frame]) -> None:
    def slower_first(request: Any, index: int) -> tuple[int, Any]:  # the first frames answer last
        time.sleep(0.02 * (len(frames) - frames_by_url[request.image_url]))
        return mcq_by_image(LABELS)(request, index)

    frames_by_url = {image_data_url(f): i for i, f in enumerate(frames)}
    with FakeServer(chat=slower_first) as server, closing(connect(server.url, max_concurrency=4)) as backend:
        answers = backend.answer_many(MCQ, frames)
    assert answers == [frame_label_of(f) for f in frames]


def test_scores_come_from_the_servers_logprobs(frames: list[Frame]) -> None:
    with FakeServer(chat=mcq_by_image(LABELS)) as server:
        client = VLMClient(connect(server.url), mcq_mode="logprob")
        try:
            answers = client.ask_many(MCQ, frames[:3])
            generated = [connect(server.url).answer(MCQ, f) for f in frames[:3]]
        finally:
            client.close()
        body = server.on(CHAT)[0].json()
    assert body["logprobs"] is True and body["top_logprobs"] == 20
    assert [a.text for a in answers] == generated
    assert all(a.confidence is not None and a.confidence >= 2.95 for a in answers)  # -0.05 against <= -3.0
    assert client.stats.scored == 3 and "MCQ by option log-probability" in client.label


def test_a_server_without_logprobs_falls_back_to_generation_in_auto(
    frames: list[Frame], caplog: pytest.LogCaptureFixture
) -> None:
    with FakeServer(chat=mcq_by_image(LABELS, logprobs=False)) as server:
        client = VLMClient(connect(server.url), mcq_mode="auto")
        try:
            with caplog.at_level(logging.WARNING, logger="vlmrl_cli.vlm.openai_compat"):
                first = client.ask_many(MCQ, frames[:2])
            later = client.ask_many(MCQ, frames[2:4])
        finally:
            client.close()
        bodies = [r.json() for r in server.on(CHAT)]
    assert "returned no log-probabilities" in caplog.text and caplog.text.count("no log-probabilities") == 1
    assert all(a.confidence is None for a in first + later)
    assert [a.text for a in first + later] == [frame_label_of(f) for f in frames[:4]]
    assert client.stats.generated == 4 and client.stats.scored == 0 and "MCQ by generation" in client.label
    assert not any(b.get("logprobs") for b in bodies[-2:])  # it no longer asks for them


def frame_label_of(frame: Frame) -> str:
    return image_label(image_data_url(frame), LABELS)


def test_a_server_without_logprobs_is_one_line_in_logprob_mode(frames: list[Frame]) -> None:
    with FakeServer(chat=mcq_by_image(LABELS, logprobs=False)) as server:
        client = VLMClient(connect(server.url), mcq_mode="logprob")
        try:
            with pytest.raises(BackendUnavailable) as exc:
                client.ask_many(MCQ, frames[:2])
        finally:
            client.close()
    msg = str(exc.value)
    assert "\n" not in msg and "returned no log-probabilities" in msg and "vlm.mcq_mode=auto" in msg


def test_a_server_error_in_a_round_is_one_line(frames: list[Frame]) -> None:
    def fails_third(request: Any, index: int) -> tuple[int, Any]:
        return (500, {"error": {"message": "boom"}}) if index == 2 else (200, completion("BOTTOM"))

    with FakeServer(chat=fails_third) as server, closing(connect(server.url, max_concurrency=4)) as backend, \
            pytest.raises(BackendUnavailable, match=r"kept failing \(HTTP 500, 1 attempt\(s\)\)") as exc:
        backend.answer_many(MCQ, frames[:6])
    assert "\n" not in str(exc.value)


def test_a_transient_error_is_retried_within_the_round(frames: list[Frame]) -> None:
    with FakeServer(chat=fail_then(2, 503, mcq_by_image(LABELS))) as server, \
            closing(connect(server.url, max_concurrency=4, retries=3)) as backend:
        answers = backend.answer_many(MCQ, frames[:4])
    assert answers == [frame_label_of(f) for f in frames[:4]]


def test_a_timeout_in_a_round_is_one_line_and_bounded(frames: list[Frame]) -> None:
    with FakeServer(chat=mcq_by_image(LABELS, latency_s=1.0)) as server, \
            closing(connect(server.url, max_concurrency=4, timeout_s=0.2)) as backend:
        start = time.perf_counter()
        with pytest.raises(BackendUnavailable, match=r"unreachable \(ReadTimeout") as exc:
            backend.score_many(MCQ, frames[:4])
    assert "\n" not in str(exc.value)
    assert time.perf_counter() - start < 3.0


def test_malformed_logprobs_count_as_none(frames: list[Frame]) -> None:
    body = completion("BOTTOM")
    body["choices"][0]["logprobs"] = {"content": [{"token": 3}]}
    with FakeServer(chat=status_only(200, body)) as server, closing(connect(server.url)) as backend:
        assert backend.score_many(MCQ, frames[:1]) == [None] and not backend.can_score


def test_concurrency_below_one_is_refused() -> None:
    with pytest.raises(BadInput, match="max_concurrency"):
        OpenAIBackend("http://127.0.0.1:9/v1", "m", max_concurrency=0)
