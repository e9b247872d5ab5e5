"""Transcripts: what is written reads back; malformed files are BadInput."""

from __future__ import annotations

from pathlib import Path

import pytest

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.vlm.transcript import TranscriptRecord, TranscriptWriter, read_transcript


def _record(answer: str) -> TranscriptRecord:
    return TranscriptRecord(backend="sim", model="m", prompt_kind="mcq", prompt="p", image_sha256="h",
                            answer=answer, latency_s=0.01, simulated=True, frame_id="x=-0.50")


def test_written_records_read_back(tmp_path: Path) -> None:
    path = tmp_path / "sub" / "t.jsonl"
    writer = TranscriptWriter(path)
    writer.write(_record("BOTTOM"))
    writer.write(_record("Choice = GOAL\nwith a newline"))
    writer.close()
    assert read_transcript(path) == [_record("BOTTOM"), _record("Choice = GOAL\nwith a newline")]


def test_unknown_fields_are_ignored(tmp_path: Path) -> None:
    path = tmp_path / "t.jsonl"
    path.write_text('{"backend": "b", "model": "m", "prompt_kind": "float", "prompt": "p", "image_sha256": "h", '
                    '"answer": "0.1", "latency_s": 0, "simulated": false, "extra": 1}\n')
    assert read_transcript(path)[0].answer == "0.1"


@pytest.mark.parametrize("content", ["garbage\n", '{"backend": "b"}\n', "\n\n"])
def test_malformed_is_bad_input(tmp_path: Path, content: str) -> None:
    path = tmp_path / "t.jsonl"
    path.write_text(content)
    with pytest.raises(BadInput):
        read_transcript(path)


def test_missing_file_is_bad_input(tmp_path: Path) -> None:
    with pytest.raises(BadInput):
        read_transcript(tmp_path / "nope.jsonl")


def test_closed_writer_refuses(tmp_path: Path) -> None:
    writer = TranscriptWriter(tmp_path / "t.jsonl")
    writer.close()
    with pytest.raises(ValueError):
        writer.write(_record("BOTTOM"))
