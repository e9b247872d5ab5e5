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


@runtime_checkable
class Backend(Protocol):
    """A VLM: ``answer`` maps (prompt, frame) to raw text; nothing else is shared.

    ``name`` is the backend kind (``sim``, ``hf``, ``openai``, ``replay``), ``model`` names the
    model (hub id, path, server model), ``simulated`` is True when no real VLM produced the
    text. Implementations raise ``BackendUnavailable`` when they cannot answer at all
    (server down, malformed response) and ``MissingAnswer`` (replay only) for an unknown query.
    """

    name: str
    model: str
    simulated: bool

    def answer(self, prompt: Prompt, frame: Frame) -> str: ...

    def close(self) -> None: ...


@runtime_checkable
class BatchBackend(Backend, Protocol):
    """A backend that answers several frames in one call (a batched forward pass, concurrent
    requests): ``answer_many(prompt, frames)[i]`` is what ``answer(prompt, frames[i])`` would say,
    whatever the split. A backend without it is asked one frame at a time (``answer_all``)."""

    def answer_many(self, prompt: Prompt, frames: Sequence[Frame]) -> list[str]: ...


def answer_all(backend: Backend, prompt: Prompt, frames: Sequence[Frame]) -> list[str]:
    """``backend``'s answers about ``frames``, in order: one ``answer_many`` call where the backend
    has it, else one ``answer`` per frame, in order (a stochastic backend's draws follow that order).

    Example:
        >>> class Echo:
        ...     name, model, simulated = "echo", "e", True
        ...     def answer(self, prompt, frame): return frame
        ...     def close(self): pass
        >>> answer_all(Echo(), None, ["a", "b"])
        ['a', 'b']
    """
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
