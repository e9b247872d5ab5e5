"""Errors that the CLI turns into one sentence on stderr and exit code 2."""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Sequence
from typing import TypeVar

T = TypeVar("T")


class BadInput(Exception):
    """A problem the user can fix, in one sentence saying how; the CLI prints it alone and exits 2."""


class BackendUnavailable(BadInput):
    """A VLM backend cannot be reached or loaded (server down, model path missing)."""


class MissingAnswer(LookupError):
    """A replay transcript holds no answer for this (prompt, frame)."""


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``choices``, or ``""`` when none is close.

    Example:
        >>> did_you_mean("nenvs", ["n_envs", "n_steps"])
        " (did you mean 'n_envs'?)"
        >>> did_you_mean("colour", ["arms", "seeds"])
        ''
    """
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


def first_repeated(values: Sequence[T]) -> T | None:
    """The first of ``values`` that an earlier one equals (the second 5 of ``5, 5``), or None.

    Example:
        >>> first_repeated([5.0, 25.0, 5]), first_repeated(["a", "b"])
        (5, None)
    """
    return next((v for i, v in enumerate(values) if v in values[:i]), None)
