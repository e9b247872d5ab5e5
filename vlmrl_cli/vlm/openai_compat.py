"""Any OpenAI-compatible chat-completions server, greedy, transient failures retried with backoff; the
API key is read from the environment per request, never stored or shown. See docs/real-vlm.md."""

from __future__ import annotations

import base64
import contextlib
import logging
import os
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

import httpx
from tenacity import Retrying, retry_if_exception_type, stop_after_attempt, wait_exponential

from vlmrl_cli.core.errors import BackendUnavailable, BadInput
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.vlm.base import OptionScores
from vlmrl_cli.vlm.config import VLMConfig
from vlmrl_cli.vlm.prompts import Prompt

DEFAULT_BACKOFF_S = 0.5
MAX_BACKOFF_S = 10.0
#: Alternatives asked for at each token when scoring an MCQ (20 is OpenAI's maximum).
TOP_LOGPROBS = 20

logger = logging.getLogger(__name__)
T = TypeVar("T")


class _Transient(Exception):
    """An HTTP status worth retrying (429, 5xx): ``args[0]``."""


class _KeptFailing(BackendUnavailable):
    """The server answered, but only with 429/5xx until the retries ran out."""


def _display_url(url: str) -> str:
    """``url`` without any ``user:password@`` part."""
    parsed = httpx.URL(url)
    return str(parsed.copy_with(username=None, password=None)) if parsed.userinfo else url


def _server_message(response: httpx.Response, limit: int = 160) -> str:
    """The server's own error text (OpenAI ``{"error": {"message": ...}}`` or plain), one line."""
    try:
        body: Any = response.json()
    except ValueError:
        body = response.text
    if isinstance(body, dict):
        err = body.get("error", body.get("detail", body.get("message", "")))
        body = err.get("message", "") if isinstance(err, dict) else err
    text = " ".join(str(body).split())
    return text[:limit].rstrip(". ")


def _content(payload: Any) -> str | None:
    """``choices[0].message.content`` as text, or None when the payload has no such string."""
    try:
        content = payload["choices"][0]["message"]["content"]
    except (KeyError, IndexError, TypeError):
        return None
    if isinstance(content, str):
        return content
    if isinstance(content, list):  # some servers answer in content parts
        texts = [str(p["text"]) for p in content if isinstance(p, dict) and isinstance(p.get("text"), str)]
        return "".join(texts) if texts else None
    return None


def _logprob_steps(payload: Any) -> list[tuple[str, float, dict[str, float]]] | None:
    """(token, log-probability, top alternatives' log-probabilities) per generated token, or None."""
    try:
        steps = [(str(item["token"]), float(item["logprob"]),
                  {str(t["token"]): float(t["logprob"]) for t in item.get("top_logprobs") or []})
                 for item in payload["choices"][0]["logprobs"]["content"]]
    except (KeyError, IndexError, TypeError, ValueError):
        return None
    return steps or None


def _completes(text: str, option: str) -> bool:
    """Whether ``text`` is ``option`` whole, perhaps followed by punctuation or space."""
    rest = text[len(option):] if text.startswith(option) else None
    return rest is not None and not (rest[:1].isalnum() or rest[:1] == "_")


def option_logprobs(steps: Sequence[tuple[str, float, Mapping[str, float]]],
                    options: Sequence[str]) -> tuple[float, ...]:
    """Each option's log-probability from a greedy completion's ``steps`` (``_logprob_steps``).

    An option follows the decoded tokens while they spell it; where it branches off, its bound is
    the best alternative spelling it, else the least listed one. Distinct first tokens are exact.

    Example:
        >>> steps = [(" LEFT", -0.2, {" LEFT": -0.2, " BOTTOM": -1.9, " GO": -4.0}),
        ...          ("_SLOPE", -0.1, {"_SLOPE": -0.1, "_PEAK": -2.4})]
        >>> option_logprobs(steps, ["LEFT_PEAK", "LEFT_SLOPE", "BOTTOM", "GOAL", "NEAR_GOAL"])
        (-2.6, -0.30000000000000004, -1.9, -4.0, -4.0)
    """
    scores = []
    for option in options:
        text, total, score = "", 0.0, None
        for token, logprob, top in steps:
            alternatives = {**top, token: logprob}
            ends = [lp for t, lp in alternatives.items() if _completes((text + t).lstrip(), option)]
            if ends:
                score = total + max(ends)
                break
            if option.startswith((text + token).lstrip()):
                text, total = text + token, total + logprob
                continue
            partial = [lp for t, lp in alternatives.items() if option.startswith((text + t).lstrip())]
            score = total + (max(partial) if partial else min(alternatives.values()))
            break
        scores.append(total if score is None else score)
    return tuple(scores)


def image_data_url(frame: Frame) -> str:
    """``frame`` as a ``data:image/png;base64,...`` URL (the OpenAI vision image format)."""
    return "data:image/png;base64," + base64.b64encode(frame.png_bytes()).decode("ascii")


class OpenAIBackend:
    """A VLM behind ``{base_url}/chat/completions``; ``retries`` after the first attempt."""

    name = "openai"
    simulated = False

    def __init__(
        self,
        base_url: str,
        model: str,
        *,
        api_key_env: str | None = None,
        timeout_s: float = 30.0,
        retries: int = 3,
        max_tokens: int = 32,
        backoff_s: float = DEFAULT_BACKOFF_S,
        transport: httpx.BaseTransport | None = None,
        max_concurrency: int = 8,
    ) -> None:
        if not base_url:
            raise BadInput("the openai backend needs --base-url, e.g. http://localhost:11434/v1 for Ollama.")
        if not base_url.startswith(("http://", "https://")):
            raise BadInput(f"--base-url must be an http(s) URL such as http://localhost:11434/v1, not '{base_url}'.")
        if not model:
            raise BadInput("the openai backend needs --model: the model name the server serves (e.g. llava).")
        if retries < 0 or timeout_s <= 0 or backoff_s < 0:
            raise BadInput("--retries must be >= 0 and --timeout > 0.")
        if max_concurrency < 1:
            raise BadInput("vlm.max_concurrency must be >= 1 (requests in flight at once).")
        self.base_url = base_url.rstrip("/")
        self.model = model
        self.api_key_env = api_key_env
        self.retries = retries
        self.max_tokens = max_tokens
        self.backoff_s = backoff_s
        self.served_models: tuple[str, ...] = ()
        self.max_concurrency = max_concurrency
        self.can_score = True  # until the server answers a request for log-probabilities without them
        limits = httpx.Limits(max_connections=max(max_concurrency, 10), max_keepalive_connections=max_concurrency)
        self._client = httpx.Client(timeout=timeout_s, transport=transport, limits=limits)

    def __repr__(self) -> str:
        return f"OpenAIBackend(base_url={_display_url(self.base_url)!r}, model={self.model!r})"

    @classmethod
    def from_config(cls, cfg: VLMConfig, *, backoff_s: float = DEFAULT_BACKOFF_S) -> OpenAIBackend:
        """Build the backend of ``cfg`` and check that its server answers (``check``)."""
        backend = cls(
            cfg.base_url or "", cfg.model or "", api_key_env=cfg.api_key_env, timeout_s=cfg.timeout_s,
            retries=cfg.retries, max_tokens=cfg.max_new_tokens, backoff_s=backoff_s,
            max_concurrency=cfg.max_concurrency,
        )
        try:
            backend.check()
        except BaseException:
            backend.close()
            raise
        return backend

    @property
    def _where(self) -> str:
        return f"the VLM server at {_display_url(self.base_url)}"

    def _api_key(self) -> str | None:
        return (os.environ.get(self.api_key_env) or None) if self.api_key_env else None

    def _send(self, method: str, path: str, payload: dict[str, Any] | None = None) -> httpx.Response:
        """The response of one request, retried on transient failures (then ``BackendUnavailable``)."""
        headers = {"Accept": "application/json"}
        key = self._api_key()
        if key:
            headers["Authorization"] = f"Bearer {key}"
        retrying = Retrying(
            stop=stop_after_attempt(self.retries + 1),
            wait=wait_exponential(multiplier=self.backoff_s, max=MAX_BACKOFF_S),
            retry=retry_if_exception_type((httpx.TransportError, _Transient)),
            reraise=True,
        )
        attempts = self.retries + 1
        try:
            for attempt in retrying:
                with attempt:
                    response = self._client.request(method, self.base_url + path, json=payload, headers=headers)
                    if response.status_code == 429 or response.status_code >= 500:
                        raise _Transient(response.status_code)
                    return response
        except httpx.TransportError as exc:
            # `from None`: the httpx exception holds the request, headers (and key) included
            raise BackendUnavailable(
                f"{self._where} is unreachable ({type(exc).__name__}, {attempts} attempt(s)); "
                "check --base-url or start the server."
            ) from None
        except _Transient as exc:
            raise _KeptFailing(
                f"{self._where} kept failing (HTTP {exc.args[0]}, {attempts} attempt(s)); "
                "check the server's logs, or retry later with more --retries."
            ) from None
        raise AssertionError("unreachable: tenacity either returns or re-raises")  # pragma: no cover

    def _refused(self, response: httpx.Response) -> BackendUnavailable:
        """The one-sentence error of a 4xx answer, with a hint per status."""
        status = response.status_code
        key = self._api_key()
        said = _server_message(response)
        said = f": {said.replace(key, '***') if key else said}" if said else ""  # a server may echo the key
        if status in (401, 403):
            hint = (f"set the API key in the environment variable {self.api_key_env} (see --api-key-env)"
                    if not key else f"check the API key in {self.api_key_env}")
        elif status == 404:
            served = f" (it serves: {', '.join(self.served_models[:8])})" if self.served_models else ""
            hint = f"check --model '{self.model}'{served} and --base-url (usually ending in /v1)"
        else:
            hint = f"check --model '{self.model}' and that the server accepts images"
        return BackendUnavailable(f"{self._where} refused the request (HTTP {status}{said}); {hint}.")

    def check(self) -> None:
        """``GET /models``: unreachable or 401/403 raise; other failures pass (the route is optional)."""
        try:
            response = self._send("GET", "/models")
        except _KeptFailing:
            return  # a failing /models route alone: chat completions may still work
        if response.status_code in (401, 403):
            raise self._refused(response)
        if response.is_success:
            with contextlib.suppress(ValueError, AttributeError, TypeError):  # no list: no hints
                data = response.json().get("data", [])
                self.served_models = tuple(str(m["id"]) for m in data if isinstance(m, dict) and "id" in m)

    def _payload(self, prompt: Prompt, frame: Frame, *, logprobs: bool = False) -> dict[str, Any]:
        payload: dict[str, Any] = {
            "model": self.model,
            "messages": [{
                "role": "user",
                "content": [
                    {"type": "image_url", "image_url": {"url": image_data_url(frame)}},
                    {"type": "text", "text": prompt.text},
                ],
            }],
            "temperature": 0,
            "max_tokens": self.max_tokens,
            "stream": False,
        }
        if logprobs:
            payload |= {"logprobs": True, "top_logprobs": TOP_LOGPROBS}
        return payload

    def _complete(self, payload: dict[str, Any]) -> Any:
        """The JSON body of a successful chat completion; ``BackendUnavailable`` otherwise."""
        response = self._send("POST", "/chat/completions", payload)
        if not response.is_success:
            raise self._refused(response)
        try:
            body = response.json()
        except ValueError:  # json.JSONDecodeError included
            body = None
        if _content(body) is None:
            raise BackendUnavailable(
                f"{self._where} returned a malformed response (no JSON choices[0].message.content); "
                "check that --base-url points at an OpenAI-compatible /v1 endpoint."
            )
        return body

    def answer(self, prompt: Prompt, frame: Frame) -> str:
        text = _content(self._complete(self._payload(prompt, frame)))
        assert text is not None  # _complete checked it
        return text

    def _in_flight(self, ask: Callable[[Frame], T], frames: Sequence[Frame]) -> list[T]:
        """``ask`` of each frame in order, ``max_concurrency`` in flight; the first failure drops the rest."""
        if len(frames) <= 1 or self.max_concurrency == 1:
            return [ask(f) for f in frames]
        pool = ThreadPoolExecutor(max_workers=min(self.max_concurrency, len(frames)),
                                  thread_name_prefix="vlmrl-openai")
        try:
            return list(pool.map(ask, frames))
        finally:
            pool.shutdown(wait=True, cancel_futures=True)

    def answer_many(self, prompt: Prompt, frames: Sequence[Frame]) -> list[str]:
        return self._in_flight(lambda frame: self.answer(prompt, frame), frames)

    def score(self, prompt: Prompt, frame: Frame) -> OptionScores | None:
        """The options scored from a completion's log-probabilities; None (and no more tries) if none."""
        assert prompt.options is not None
        body = self._complete(self._payload(prompt, frame, logprobs=True))
        steps = _logprob_steps(body)
        if steps is None:
            if self.can_score:
                logger.warning("%s returned no log-probabilities; the MCQ is answered by generation instead",
                               self._where)
            self.can_score = False
            return None
        return OptionScores(prompt.options, option_logprobs(steps, prompt.options))

    def score_many(self, prompt: Prompt, frames: Sequence[Frame]) -> list[OptionScores | None]:
        return self._in_flight(lambda frame: self.score(prompt, frame), frames)

    def close(self) -> None:
        self._client.close()
