"""A backend wrapped with the response cache and the transcript: what callers use."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from vlmrl_cli.frames.render import Frame
from vlmrl_cli.vlm.base import Answer, Backend, describe
from vlmrl_cli.vlm.cache import ResponseCache, cache_key
from vlmrl_cli.vlm.prompts import Prompt
from vlmrl_cli.vlm.transcript import TranscriptRecord, TranscriptWriter


@dataclass
class ClientStats:
    queries: int = 0
    cache_hits: int = 0
    cache_misses: int = 0
    backend_seconds: float = 0.0


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
        self.stats.queries += 1
        b = self.backend
        key = cache_key(b.name, b.model, prompt.text, frame.sha256)
        hit = self.cache.get(key) if self.cache is not None else None
        if hit is not None:
            self.stats.cache_hits += 1
            text, latency, cached = hit[0], hit[1], True
        else:
            self.stats.cache_misses += 1
            start = time.perf_counter()
            text = b.answer(prompt, frame)
            latency = time.perf_counter() - start
            self.stats.backend_seconds += latency
            cached = False
            if self.cache is not None:
                self.cache.put(key, b.name, b.model, text, latency)
        if self.transcript is not None:
            self.transcript.write(
                TranscriptRecord(
                    backend=b.name, model=b.model, prompt_kind=prompt.kind.value,
                    prompt=prompt.text, image_sha256=frame.sha256, answer=text,
                    latency_s=latency, simulated=b.simulated, cached=cached,
                    frame_id=frame.frame_id,
                )
            )
        return Answer(text=text, latency_s=latency, backend=b.name, model=b.model,
                      simulated=b.simulated, cached=cached)

    def close(self) -> None:
        if self.transcript is not None:
            self.transcript.close()
        if self.cache is not None:
            self.cache.close()
        self.backend.close()
