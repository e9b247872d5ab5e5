"""Replay a recorded transcript as a backend: the paper's Table 1 outputs, or any earlier run."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from vlmrl_cli.core.errors import BadInput, MissingAnswer
from vlmrl_cli.frames.render import Frame
from vlmrl_cli.vlm.config import PAPER_TRANSCRIPT, VLMConfig
from vlmrl_cli.vlm.prompts import Prompt
from vlmrl_cli.vlm.transcript import TranscriptRecord, read_transcript


class ReplayBackend:
    """Answers from a transcript by (prompt kind, image SHA-256), else frame id; ``simulated`` if any was."""

    name = "replay"

    def __init__(self, records: Sequence[TranscriptRecord], source: Path | None = None) -> None:
        if not records:
            raise BadInput("the replay transcript holds no records.")
        self.source = source
        self.records = tuple(records)
        self.model = "+".join(dict.fromkeys(r.model for r in records))
        self.simulated = any(r.simulated for r in records)
        # the first record wins on duplicates: a transcript that re-asks a cached query repeats it
        self._by_sha: dict[tuple[str, str], str] = {}
        self._by_id: dict[tuple[str, str], str] = {}
        for r in records:
            self._by_sha.setdefault((r.prompt_kind, r.image_sha256), r.answer)
            if r.frame_id is not None:
                self._by_id.setdefault((r.prompt_kind, r.frame_id), r.answer)

    @classmethod
    def from_config(cls, cfg: VLMConfig) -> ReplayBackend:
        """Read ``cfg.transcript_in`` (default: the paper's Table 1 transcript)."""
        path = cfg.transcript_in if cfg.transcript_in is not None else PAPER_TRANSCRIPT
        return cls(read_transcript(path), source=path)

    def frame_ids(self) -> list[str]:
        """The recorded frame ids, in the order they first appear."""
        return list(dict.fromkeys(r.frame_id for r in self.records if r.frame_id is not None))

    def answer(self, prompt: Prompt, frame: Frame) -> str:
        kind = prompt.kind.value
        text = self._by_sha.get((kind, frame.sha256))
        if text is None and frame.frame_id is not None:
            text = self._by_id.get((kind, frame.frame_id))
        if text is None:
            raise MissingAnswer(f"the transcript has no {kind} answer for frame {frame.frame_id or frame.sha256[:12]}")
        return text

    def close(self) -> None:
        pass
