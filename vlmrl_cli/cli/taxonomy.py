"""`vlmrl taxonomy` (being built)."""

from __future__ import annotations


def taxonomy() -> None:
    """Not implemented yet."""
    raise SystemExit(2)
