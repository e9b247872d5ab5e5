"""`vlmrl run` (being built)."""

from __future__ import annotations


def run() -> None:
    """Not implemented yet."""
    raise SystemExit(2)
