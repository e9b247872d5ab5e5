"""A persistent response cache shared by all backends (sqlite, one table)."""

from __future__ import annotations

import hashlib
import sqlite3
import time
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
    """sqlite-backed map from ``cache_key`` to (answer, original latency)."""

    def __init__(self, path: Path, batch: int = 64, max_age_s: float = 5.0) -> None:
        if batch < 1 or not max_age_s >= 0:
            raise ValueError(f"batch must be >= 1 answer and max_age_s >= 0, got {batch} and {max_age_s}")
        self.path = path
        self.batch = int(batch)
        self.max_age_s = float(max_age_s)
        self._oldest = 0.0  # time.monotonic() of the oldest pending answer
        self._pending: dict[str, tuple[str, str, str, float]] = {}
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(str(path), timeout=30.0)
            self._db.execute("PRAGMA journal_mode=WAL")
            # no fsync per commit (~190 ms on a busy disk): a crash loses answers, never the file
            self._db.execute("PRAGMA synchronous=NORMAL")
            self._db.execute(_SCHEMA)
            self._db.commit()
        except (OSError, sqlite3.Error) as exc:
            raise BadInput(f"cannot open the response cache {path}; pass --no-cache or a writable path.") from exc

    def get(self, key: str) -> tuple[str, float] | None:
        if key in self._pending:
            return self._pending[key][2], self._pending[key][3]
        row = self._db.execute("SELECT answer, latency_s FROM responses WHERE key = ?", (key,)).fetchone()
        return None if row is None else (str(row[0]), float(row[1]))

    def put(self, key: str, backend: str, model: str, answer: str, latency_s: float) -> None:
        """Store an answer; written in batches of ``batch`` or after ``max_age_s`` (served from memory till then)."""
        now = time.monotonic()
        if not self._pending:
            self._oldest = now
        self._pending[key] = (backend, model, answer, float(latency_s))
        if len(self._pending) >= self.batch or now - self._oldest >= self.max_age_s:
            self.flush()

    def flush(self) -> None:
        if not self._pending:
            return
        rows = [(key, *value) for key, value in self._pending.items()]
        with self._db:
            self._db.executemany("INSERT OR REPLACE INTO responses VALUES (?, ?, ?, ?, ?)", rows)
        self._pending.clear()

    def close(self) -> None:
        try:
            self.flush()
        finally:
            self._db.close()
