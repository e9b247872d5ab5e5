"""`vlmrl report` (being built)."""

from __future__ import annotations


def report() -> None:
    """Not implemented yet."""
    raise SystemExit(2)
