"""JSONL transcripts of VLM queries: every backend writes one, ``replay`` reads one."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import IO

from vlmrl_cli.core.errors import BadInput


@dataclass(frozen=True)
class TranscriptRecord:
    """One query: what was asked about which image, what came back, how fast, from whom."""

    backend: str
    model: str
    prompt_kind: str
    prompt: str
    image_sha256: str
    answer: str
    latency_s: float
    simulated: bool
    cached: bool = False
    frame_id: str | None = None
    note: str | None = None
    confidence: float | None = None  # an MCQ scored by option log-probability: best minus second


class TranscriptWriter:
    """Appends records to a JSONL file, one per line, flushed as written."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._fh: IO[str] | None = path.open("a", encoding="utf-8")
        except OSError as exc:
            raise BadInput(f"cannot write the transcript {path}: {exc.strerror}.") from exc

    def write(self, record: TranscriptRecord) -> None:
        if self._fh is None:
            raise ValueError("transcript writer is closed")
        fields = asdict(record)
        if fields["confidence"] is None:  # written only where there is one: older lines stay as they were
            del fields["confidence"]
        self._fh.write(json.dumps(fields, sort_keys=True) + "\n")
        self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def read_transcript(path: Path) -> list[TranscriptRecord]:
    """Read a JSONL transcript; any unreadable file or line is a ``BadInput``."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise BadInput(f"cannot read the transcript {path}; pass a JSONL file written by vlmrl.") from exc
    records: list[TranscriptRecord] = []
    fields = set(TranscriptRecord.__dataclass_fields__)
    for lineno, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            raw = json.loads(line)
            if not isinstance(raw, dict):
                raise TypeError("not an object")
            records.append(TranscriptRecord(**{k: v for k, v in raw.items() if k in fields}))
        except (ValueError, TypeError) as exc:
            raise BadInput(
                f"the transcript {path} is malformed at line {lineno}; each line must be a JSON "
                "record with backend, model, prompt_kind, prompt, image_sha256, answer, latency_s."
            ) from exc
    if not records:
        raise BadInput(f"the transcript {path} holds no records.")
    return records
