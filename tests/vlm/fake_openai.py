"""A real OpenAI-compatible HTTP server on loopback, for tests: canned or scripted answers.

``FakeServer`` runs ``http.server.ThreadingHTTPServer`` on ``127.0.0.1`` port 0 in a daemon
thread, records every request (method, path, headers, body) and answers
``POST /v1/chat/completions`` and ``GET /v1/models`` through small responder functions, so
tests can script outages (503 then 200), malformed JSON, 4xx and so on.
"""

from __future__ import annotations

import hashlib
import json
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

from vlmrl_cli.tasks.mountain_car.prompts import PROMPTS
from vlmrl_cli.vlm.prompts import PromptKind

Body = bytes | str | dict[str, Any]
# (the request, its 0-based index among requests to the same route) -> (HTTP status, body)
Responder = Callable[["Recorded", int], tuple[int, Body]]

CANNED: dict[PromptKind, str] = {
    PromptKind.FLOAT: "-0.52",
    PromptKind.BOX: "[120, 200, 180, 260]",
    PromptKind.MCQ: "BOTTOM",
}


@dataclass(frozen=True)
class Recorded:
    """One request the server received."""

    method: str
    path: str
    headers: dict[str, str]
    body: bytes

    def json(self) -> Any:
        return json.loads(self.body)

    @property
    def prompt_text(self) -> str:
        """The text part of the (single) user message of a chat-completions request."""
        parts = self.json()["messages"][0]["content"]
        return next(p["text"] for p in parts if p["type"] == "text")

    @property
    def image_url(self) -> str:
        """The image URL of the (single) user message of a chat-completions request."""
        parts = self.json()["messages"][0]["content"]
        return next(p["image_url"]["url"] for p in parts if p["type"] == "image_url")


def completion(content: Any, model: str = "m") -> dict[str, Any]:
    """A minimal chat-completions response body whose first choice says ``content``."""
    return {
        "id": "chatcmpl-test", "object": "chat.completion", "model": model,
        "choices": [{"index": 0, "message": {"role": "assistant", "content": content}, "finish_reason": "stop"}],
    }


def canned_answer(request: Recorded, index: int) -> tuple[int, Body]:
    """Answer each probe prompt with a well-formed, plausible answer (see ``CANNED``)."""
    text = request.prompt_text
    kind = next((k for k, p in PROMPTS.items() if p.text == text), PromptKind.MCQ)
    return 200, completion(CANNED[kind], model=request.json().get("model", "m"))


def image_label(image_url: str, labels: tuple[str, ...]) -> str:
    """A label per image, fixed by the image's bytes: different frames get different labels."""
    return labels[int(hashlib.sha256(image_url.encode()).hexdigest(), 16) % len(labels)]


def mcq_by_image(labels: tuple[str, ...], *, latency_s: float = 0.0, logprobs: bool = True) -> Responder:
    """A server that answers after ``latency_s`` seconds with one label per image
    (``frame_label``) and, when asked (``"logprobs": true``) and ``logprobs``, the log-probability
    of each label as its one token (`` LABEL``, the answer's at -0.05, the others lower)."""

    def respond(request: Recorded, index: int) -> tuple[int, Body]:
        time.sleep(latency_s)
        label = image_label(request.image_url, labels)
        body = completion(label, model=request.json().get("model", "m"))
        if logprobs and request.json().get("logprobs"):
            top = [{"token": " " + option, "logprob": -0.05 if option == label else -3.0 - 0.5 * i}
                   for i, option in enumerate(labels)][: int(request.json().get("top_logprobs", 0))]
            step = {"token": " " + label, "logprob": -0.05, "top_logprobs": top}
            body["choices"][0]["logprobs"] = {"content": [step]}
        return 200, body

    return respond


def list_models(*names: str) -> Responder:
    """A ``GET /models`` responder listing ``names``."""

    def respond(request: Recorded, index: int) -> tuple[int, Body]:
        return 200, {"object": "list", "data": [{"id": n, "object": "model"} for n in names]}

    return respond


def status_only(status: int, body: Body = b"") -> Responder:
    """A responder that always answers ``status`` with ``body``."""
    return lambda request, index: (status, body)


def fail_then(failures: int, status: int, then: Responder) -> Responder:
    """Answer ``status`` to the first ``failures`` requests, then delegate to ``then``."""

    def respond(request: Recorded, index: int) -> tuple[int, Body]:
        return (status, {"error": {"message": "overloaded"}}) if index < failures else then(request, index)

    return respond


@dataclass
class FakeServer:
    """An OpenAI-compatible server on ``127.0.0.1``; use as a context manager.

    ``url`` is the base URL to pass as ``--base-url`` (ends in ``/v1``); ``requests`` holds
    every request received, in order.
    """

    chat: Responder = canned_answer
    models: Responder = field(default_factory=lambda: list_models("m"))
    requests: list[Recorded] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._lock = threading.Lock()
        self._server: ThreadingHTTPServer | None = None
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        assert self._server is not None, "start the server first (use it as a context manager)"
        return f"http://127.0.0.1:{self._server.server_address[1]}/v1"

    def on(self, path: str) -> list[Recorded]:
        """The requests received on ``path`` (e.g. ``/v1/chat/completions``)."""
        with self._lock:
            return [r for r in self.requests if r.path == path]

    def _handle(self, method: str, path: str, headers: dict[str, str], body: bytes) -> tuple[int, bytes]:
        request = Recorded(method, path, headers, body)
        with self._lock:
            index = sum(1 for r in self.requests if r.path == path)
            self.requests.append(request)
        if method == "POST" and path == "/v1/chat/completions":
            status, out = self.chat(request, index)
        elif method == "GET" and path == "/v1/models":
            status, out = self.models(request, index)
        else:
            status, out = 404, {"error": {"message": f"no route {method} {path}"}}
        if isinstance(out, dict):
            out = json.dumps(out)
        return status, out.encode() if isinstance(out, str) else out

    def __enter__(self) -> FakeServer:
        owner = self

        class Handler(BaseHTTPRequestHandler):
            def _serve(self, method: str) -> None:
                length = int(self.headers.get("Content-Length") or 0)
                body = self.rfile.read(length) if length else b""
                headers = {k.lower(): v for k, v in self.headers.items()}
                status, out = owner._handle(method, self.path, headers, body)
                try:
                    self.send_response(status)
                    self.send_header("Content-Type", "application/json")
                    self.send_header("Content-Length", str(len(out)))
                    self.end_headers()
                    self.wfile.write(out)
                except (BrokenPipeError, ConnectionResetError):
                    pass  # the client already gave up (the timeout tests): nothing left to answer

            def do_GET(self) -> None:
                self._serve("GET")

            def do_POST(self) -> None:
                self._serve("POST")

            def log_message(self, format: str, *args: Any) -> None:  # keep test output quiet
                pass

        self._server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self._server.daemon_threads = True
        self._thread = threading.Thread(target=self._server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        assert self._server is not None and self._thread is not None
        self._server.shutdown()
        self._server.server_close()
        self._thread.join(timeout=5)


def down_url() -> str:
    """The base URL of a loopback port that was bound and then closed: nothing listens there."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    return f"http://127.0.0.1:{port}/v1"
