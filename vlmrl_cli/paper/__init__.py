"""The paper's own data, shipped inside the package (read through ``importlib.resources``).

``REPORTED``: the numbers the paper reports (Table 2, claims, Table 1), the one source the
report compares against. ``TABLE1_TRANSCRIPT``: the raw VLM outputs the paper prints in
Table 1, replayed by ``--vlm replay``. The paper itself is summarised, with its citation, in
the repository's ``paper/README.md``.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

_HERE = files(__name__)
REPORTED = Path(str(_HERE / "reported.json"))
TABLE1_TRANSCRIPT = Path(str(_HERE / "table1_transcript.jsonl"))
