"""A backend wrapped with the response cache and the transcript: what callers use."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from vlmrl_cli.frames.render import Frame
from vlmrl_cli.vlm.base import Answer, Backend, answer_all, describe
from vlmrl_cli.vlm.cache import ResponseCache, cache_key
from vlmrl_cli.vlm.prompts import Prompt
from vlmrl_cli.vlm.transcript import TranscriptRecord, TranscriptWriter


@dataclass
class ClientStats:
    """What a client did: queries asked (cache hits included), the backend calls they took and
    how many frames those carried, and the seconds spent waiting for the backend."""

    queries: int = 0
    cache_hits: int = 0
    cache_misses: int = 0
    backend_seconds: float = 0.0
    backend_calls: int = 0
    backend_frames: int = 0
    largest_batch: int = 0


class VLMClient:
    """Ask a backend about a frame, through the cache, writing every query to the transcript.

    ``ask`` is the only entry point; ``MissingAnswer`` and ``BackendUnavailable`` from the
    backend propagate to the caller. The replay backend is never cached (it is a cache), and
    neither is a ``stochastic`` one (its next answer to the same query may differ).
    """

    def __init__(
        self,
        backend: Backend,
        cache: ResponseCache | None = None,
        transcript: Path | None = None,
    ) -> None:
        self.backend = backend
        self.cache = cache if backend.name != "replay" and not self.stochastic else None
        self.transcript = TranscriptWriter(transcript) if transcript is not None else None
        self.stats = ClientStats()

    @property
    def stochastic(self) -> bool:
        """True when the backend may answer one query differently each time (never cached)."""
        return bool(getattr(self.backend, "stochastic", False))

    @property
    def label(self) -> str:
        return describe(self.backend)

    def ask(self, prompt: Prompt, frame: Frame) -> Answer:
        """The answer about one frame (``ask_many`` of one)."""
        return self.ask_many(prompt, [frame])[0]

    def ask_many(self, prompt: Prompt, frames: Sequence[Frame]) -> list[Answer]:
        """The answers about ``frames``, in order: each looked up in the cache, the others sent to
        the backend in ONE call (``answer_all``: a batch, concurrent requests, or one by one for a
        backend that cannot batch), a frame asked twice in the call sent once unless the backend
        is stochastic; every query written to the transcript in the order of ``frames``. The
        answers do not depend on how a caller splits its frames into calls."""
        b = self.backend
        keys = [cache_key(b.name, b.model, prompt.text, frame.sha256) for frame in frames]
        hits: dict[int, tuple[str, float]] = {}
        for i, key in enumerate(keys):
            hit = self.cache.get(key) if self.cache is not None else None
            if hit is not None:
                hits[i] = (hit[0], hit[1])
        missing = [i for i in range(len(frames)) if i not in hits]
        # one query per distinct frame, unless each query is a fresh draw
        first: dict[str, int] = {}
        send = []
        for i in missing:
            if self.stochastic or keys[i] not in first:
                first.setdefault(keys[i], i)
                send.append(i)
        start = time.perf_counter()
        texts = answer_all(b, prompt, [frames[i] for i in send]) if send else []
        elapsed = time.perf_counter() - start
        latency = elapsed / len(send) if send else 0.0
        fresh = dict(zip(send, texts, strict=True))
        if send:
            self.stats.backend_calls += 1
            self.stats.backend_frames += len(send)
            self.stats.largest_batch = max(self.stats.largest_batch, len(send))
            self.stats.backend_seconds += elapsed
        answers = []
        for i, frame in enumerate(frames):
            self.stats.queries += 1
            if i not in hits and i not in fresh and self.cache is not None:  # as a later ask would find it
                hits[i] = (fresh[first[keys[i]]], latency)
            if i in hits:
                self.stats.cache_hits += 1
                text, took, cached = hits[i][0], hits[i][1], True
            else:
                self.stats.cache_misses += 1
                text = fresh[i] if i in fresh else fresh[first[keys[i]]]
                took, cached = latency, False
                if self.cache is not None and i in fresh:
                    self.cache.put(keys[i], b.name, b.model, text, took)
            if self.transcript is not None:
                self.transcript.write(
                    TranscriptRecord(
                        backend=b.name, model=b.model, prompt_kind=prompt.kind.value,
                        prompt=prompt.text, image_sha256=frame.sha256, answer=text,
                        latency_s=took, simulated=b.simulated, cached=cached,
                        frame_id=frame.frame_id,
                    )
                )
            answers.append(Answer(text=text, latency_s=took, backend=b.name, model=b.model,
                                  simulated=b.simulated, cached=cached))
        return answers

    def close(self) -> None:
        if self.transcript is not None:
            self.transcript.close()
        if self.cache is not None:
            self.cache.close()
        self.backend.close()
