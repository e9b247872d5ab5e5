"""Errors that the CLI turns into one sentence on stderr and exit code 2."""

from __future__ import annotations


class BadInput(Exception):
    """A problem the user can fix: bad option, unreachable server, unreadable file.

    The message is one sentence that says what is wrong and how to fix it; the CLI
    prints it alone (no traceback) and exits with code 2.
    """


class BackendUnavailable(BadInput):
    """A VLM backend cannot be reached or loaded (server down, model path missing)."""


class MissingAnswer(LookupError):
    """A replay transcript holds no answer for this (prompt, frame)."""
