"""A persistent response cache shared by all backends (sqlite, one table)."""

from __future__ import annotations

import hashlib
import sqlite3
from pathlib import Path

from vlmrl_cli.core.errors import BadInput

_SCHEMA = """
CREATE TABLE IF NOT EXISTS responses (
    key TEXT PRIMARY KEY,
    backend TEXT NOT NULL,
    model TEXT NOT NULL,
    answer TEXT NOT NULL,
    latency_s REAL NOT NULL
)
"""


def cache_key(backend: str, model: str, prompt: str, image_sha256: str) -> str:
    """Key of one query: backend, model, prompt text and image bytes (via their SHA-256)."""
    blob = "\x1f".join((backend, model, prompt, image_sha256)).encode()
    return hashlib.sha256(blob).hexdigest()


class ResponseCache:
    """sqlite-backed map from ``cache_key`` to (answer, original latency); counts hits/misses.

    Example:
        >>> import tempfile, pathlib
        >>> c = ResponseCache(pathlib.Path(tempfile.mkdtemp()) / "r.sqlite")
        >>> k = cache_key("sim", "m", "p", "abc")
        >>> c.get(k) is None, c.put(k, "sim", "m", "BOTTOM", 0.1), c.get(k)
        (True, None, ('BOTTOM', 0.1))
        >>> c.hits, c.misses
        (1, 1)
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.hits = 0
        self.misses = 0
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(str(path), timeout=30.0)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute(_SCHEMA)
            self._db.commit()
        except (OSError, sqlite3.Error) as exc:
            raise BadInput(f"cannot open the response cache {path}; pass --no-cache or a writable path.") from exc

    def get(self, key: str) -> tuple[str, float] | None:
        row = self._db.execute("SELECT answer, latency_s FROM responses WHERE key = ?", (key,)).fetchone()
        if row is None:
            self.misses += 1
            return None
        self.hits += 1
        return str(row[0]), float(row[1])

    def put(self, key: str, backend: str, model: str, answer: str, latency_s: float) -> None:
        self._db.execute(
            "INSERT OR REPLACE INTO responses VALUES (?, ?, ?, ?, ?)",
            (key, backend, model, answer, latency_s),
        )
        self._db.commit()

    def close(self) -> None:
        self._db.close()
