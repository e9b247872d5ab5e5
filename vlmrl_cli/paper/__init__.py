"""The paper's own data, shipped in the package: ``REPORTED``, the numbers it reports (Table 2,
claims, Table 1), and ``TABLE1_TRANSCRIPT``, its Table 1 VLM outputs replayed by ``--vlm replay``
(the paper is summarised in the repository's ``paper/README.md``)."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

_HERE = files(__name__)
REPORTED = Path(str(_HERE / "reported.json"))
TABLE1_TRANSCRIPT = Path(str(_HERE / "table1_transcript.jsonl"))
