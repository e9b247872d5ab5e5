"""A backend wrapped with the response cache and the transcript: what callers use."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from vlmrl_cli.core.errors import BackendUnavailable, BadInput
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.vlm.base import Answer, Backend, OptionScores, ScoringBackend, answer_all, describe
from vlmrl_cli.vlm.cache import ResponseCache, cache_key
from vlmrl_cli.vlm.config import MCQ_MODES
from vlmrl_cli.vlm.prompts import Prompt
from vlmrl_cli.vlm.transcript import TranscriptRecord, TranscriptWriter

#: Appended to the model's name in the cache key of an answer scored by option log-probability.
SCORED_KEY = "#mcq-logprob"


@dataclass
class ClientStats:
    """What a client did: queries (cache hits included), backend calls, their frames and seconds."""

    queries: int = 0
    cache_hits: int = 0
    cache_misses: int = 0
    backend_seconds: float = 0.0
    backend_calls: int = 0
    backend_frames: int = 0
    largest_batch: int = 0
    scored: int = 0  # backend answers from option log-probabilities
    generated: int = 0  # backend answers decoded (every answer but a scored MCQ's)


class VLMClient:
    """Ask a backend through the cache (never for replay or a ``stochastic`` one), writing a transcript."""

    def __init__(
        self,
        backend: Backend,
        cache: ResponseCache | None = None,
        transcript: Path | None = None,
        mcq_mode: str = "auto",
    ) -> None:
        if mcq_mode not in MCQ_MODES:
            raise BadInput(f"unknown vlm.mcq_mode '{mcq_mode}'; choose one of {', '.join(MCQ_MODES)}.")
        if mcq_mode == "logprob" and not isinstance(backend, ScoringBackend):
            raise BadInput(f"vlm.mcq_mode=logprob needs a backend that scores options (hf, openai), not "
                           f"{backend.name}; set vlm.mcq_mode=auto or generate.")
        self.mcq_mode = mcq_mode
        self.backend = backend
        self.cache = cache if backend.name != "replay" and not self.stochastic else None
        self.transcript = TranscriptWriter(transcript) if transcript is not None else None
        self.stats = ClientStats()

    @property
    def stochastic(self) -> bool:
        return bool(getattr(self.backend, "stochastic", False))

    @property
    def label(self) -> str:
        """``describe(backend)``, plus how a scoring backend answers an MCQ: the runs' provenance tag."""
        if not isinstance(self.backend, ScoringBackend):
            return describe(self.backend)
        mode = "option log-probability" if self.mcq_mode != "generate" and self.backend.can_score else "generation"
        return f"{describe(self.backend)} (MCQ by {mode})"

    def ask(self, prompt: Prompt, frame: Frame) -> Answer:
        """The answer about one frame (``ask_many`` of one)."""
        return self.ask_many(prompt, [frame])[0]

    def ask_many(self, prompt: Prompt, frames: Sequence[Frame], *, generate: bool = False) -> list[Answer]:
        """The answers about ``frames``: cache misses go to the backend in ONE call, a repeated frame once
        unless stochastic; ``generate`` decodes whatever the mode."""
        b = self.backend
        scored = self.scores(prompt) and not generate
        keys = [self._key(prompt, frame, scored) for frame in frames]
        hits = {i: hit for i, key in enumerate(keys) if self.cache is not None and (hit := self.cache.get(key))}
        first: dict[str, int] = {}
        send = [i for i in range(len(frames))  # one query per distinct frame, unless each is a fresh draw
                if i not in hits and (self.stochastic or first.setdefault(keys[i], i) == i)]
        fresh, latency = self._fresh(prompt, [frames[i] for i in send], scored) if send else ([], 0.0)
        answered = dict(zip(send, fresh, strict=True))
        answers = []
        for i, frame in enumerate(frames):
            confidence: float | None = None
            if i in hits:
                (text, took), cached = hits[i], True
            else:
                text, confidence, key = answered.get(i) or answered[first[keys[i]]]
                took, cached = latency, i not in answered and self.cache is not None  # as a later ask would find it
                if cached:
                    confidence = None
                elif self.cache is not None:
                    self.cache.put(key, b.name, b.model, text, took)
            self.stats.queries += 1
            self.stats.cache_hits += cached
            self.stats.cache_misses += not cached
            if self.transcript is not None:
                self.transcript.write(TranscriptRecord(
                    backend=b.name, model=b.model, prompt_kind=prompt.kind.value, prompt=prompt.text,
                    image_sha256=frame.sha256, answer=text, latency_s=took, simulated=b.simulated, cached=cached,
                    frame_id=frame.frame_id, confidence=confidence))
            answers.append(Answer(text=text, latency_s=took, backend=b.name, model=b.model,
                                  simulated=b.simulated, cached=cached, confidence=confidence))
        return answers

    def scores(self, prompt: Prompt) -> bool:
        """Whether ``prompt`` is answered by its options' log-probabilities."""
        return (prompt.options is not None and self.mcq_mode != "generate"
                and isinstance(self.backend, ScoringBackend) and bool(self.backend.can_score))

    def mcq_mode_entry(self, prompt: Prompt) -> dict[str, str]:
        """``{"mcq.mode": "logprob" | "generate"}`` for a backend that can score, else empty."""
        if not isinstance(self.backend, ScoringBackend):
            return {}
        return {"mcq.mode": "logprob" if self.scores(prompt) else "generate"}

    def _key(self, prompt: Prompt, frame: Frame, scored: bool) -> str:
        b = self.backend
        return cache_key(b.name, b.model + (SCORED_KEY if scored else ""), prompt.text, frame.sha256)

    def _fresh(self, prompt: Prompt, frames: list[Frame], scored: bool
               ) -> tuple[list[tuple[str, float | None, str]], float]:
        """(text, confidence, cache key) of each of ``frames`` from ONE backend call, and seconds per frame."""
        start = time.perf_counter()
        results: list[OptionScores | None] = [None] * len(frames)
        if scored:
            assert isinstance(self.backend, ScoringBackend)
            results = list(self.backend.score_many(prompt, frames))
            if len(results) != len(frames):
                raise ValueError(f"{self.backend.name} scored {len(results)} of {len(frames)} frames")
        fallback = [j for j, r in enumerate(results) if r is None]
        if scored and fallback and self.mcq_mode == "logprob":
            raise BackendUnavailable(
                f"{describe(self.backend)} returned no log-probabilities for the MCQ's options "
                "(vlm.mcq_mode=logprob); serve the model where they are returned (vLLM, SGLang) or set "
                "vlm.mcq_mode=auto to generate instead.")
        texts = dict(zip(fallback, answer_all(self.backend, prompt, [frames[j] for j in fallback]), strict=True))
        self.stats.scored += len(frames) - len(fallback)
        self.stats.generated += len(fallback)
        out: list[tuple[str, float | None, str]] = [
            (texts[j], None, self._key(prompt, frame, False)) if r is None else
            (r.label, r.margin, self._key(prompt, frame, True))
            for j, (frame, r) in enumerate(zip(frames, results, strict=True))]
        elapsed = time.perf_counter() - start
        self.stats.backend_calls += 1
        self.stats.backend_frames += len(frames)
        self.stats.largest_batch = max(self.stats.largest_batch, len(frames))
        self.stats.backend_seconds += elapsed
        return out, elapsed / len(frames)

    def close(self) -> None:
        if self.transcript is not None:
            self.transcript.close()
        if self.cache is not None:
            self.cache.close()
        self.backend.close()
