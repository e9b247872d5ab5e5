"""The one interface every VLM backend implements, and what a query returns."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from vlmrl_cli.frames.render import Frame
from vlmrl_cli.vlm.prompts import Prompt


@dataclass(frozen=True)
class Answer:
    """A VLM's raw text answer to one (prompt, frame) query, with its provenance."""

    text: str
    latency_s: float
    backend: str
    model: str
    simulated: bool
    cached: bool = False
    confidence: float | None = None  # an MCQ scored by option log-probability: best minus second


@runtime_checkable
class Backend(Protocol):
    """A VLM: ``answer`` maps (prompt, frame) to raw text; ``simulated``: no real VLM wrote it.
    Raises ``BackendUnavailable``, or ``MissingAnswer`` (replay) for an unknown query."""

    name: str
    model: str
    simulated: bool

    def answer(self, prompt: Prompt, frame: Frame) -> str: ...

    def close(self) -> None: ...


@runtime_checkable
class BatchBackend(Backend, Protocol):
    """A backend that answers several frames in one call: ``answer_many(p, fs)[i] == answer(p, fs[i])``."""

    def answer_many(self, prompt: Prompt, frames: Sequence[Frame]) -> list[str]: ...


@dataclass(frozen=True)
class OptionScores:
    """An MCQ answered by scoring: each option's log-probability; the argmax is the ``label``."""

    options: tuple[str, ...]
    logprobs: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.options) != len(self.logprobs) or len(self.options) < 2:
            raise ValueError(f"{len(self.logprobs)} log-probabilities for {len(self.options)} options")

    @property
    def label(self) -> str:
        return self.options[max(range(len(self.options)), key=lambda i: (self.logprobs[i], -i))]

    @property
    def margin(self) -> float:
        """The best log-probability minus the second best: the answer's confidence."""
        best, second = sorted(self.logprobs, reverse=True)[:2]
        return best - second


@runtime_checkable
class ScoringBackend(Backend, Protocol):
    """A backend that scores an MCQ's options (None: no log-probabilities came back)."""

    can_score: bool

    def score_many(self, prompt: Prompt, frames: Sequence[Frame]) -> list[OptionScores | None]: ...


def answer_all(backend: Backend, prompt: Prompt, frames: Sequence[Frame]) -> list[str]:
    """The answers about ``frames``, in order: one ``answer_many`` call, else ``answer`` per frame."""
    if not frames:
        return []
    if isinstance(backend, BatchBackend):
        answers = backend.answer_many(prompt, frames)
        if len(answers) != len(frames):
            raise ValueError(f"{backend.name} answered {len(answers)} of {len(frames)} frames")
        return list(answers)
    return [backend.answer(prompt, frame) for frame in frames]


def describe(backend: Backend) -> str:
    """One label for tables, captions and MLflow tags, saying plainly when it is simulated.

    Example:
        >>> class B:
        ...     name, model, simulated = "sim", "pixel-reader", True
        ...     def answer(self, prompt, frame): return ""
        ...     def close(self): pass
        >>> describe(B())
        'sim:pixel-reader (SIMULATED VLM, not a real model)'
    """
    label = f"{backend.name}:{backend.model}"
    return f"{label} (SIMULATED VLM, not a real model)" if backend.simulated else label
