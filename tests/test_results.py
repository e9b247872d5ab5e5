"""The committed results: each manifest names the clean commit its numbers came from."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

RESULTS = Path(__file__).resolve().parents[1] / "results"
COMMIT = re.compile(r"[0-9a-f]{40}")


def _commits(tree: Any) -> Iterator[str]:
    if isinstance(tree, dict):
        for key, value in tree.items():
            if key == "git_commit" and isinstance(value, str):
                yield value
            else:
                yield from _commits(value)
    elif isinstance(tree, list):
        for value in tree:
            yield from _commits(value)


def test_every_committed_manifest_names_a_clean_commit() -> None:
    manifests = sorted(RESULTS.rglob("manifest.json"))
    assert manifests, "results/ holds manifests"
    bad = [(str(m.relative_to(RESULTS)), c) for m in manifests
           for c in _commits(json.loads(m.read_text(encoding="utf-8"))) if not COMMIT.fullmatch(c)]
    assert not bad, f"manifests naming no clean commit (e.g. '-dirty'): {bad}"
