"""The committed results are on the numeric pin: every run in every export under results/ was
trained on the pin this package applies (issue 27), so `vlmrl verify` can reproduce it anywhere."""
from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest

from vlmrl_cli.core.numeric_pin import PIN_ID
from vlmrl_cli.tracking.transfer import read_records

RESULTS = Path(__file__).resolve().parents[1] / "results"
EXPORTS = sorted(RESULTS.rglob("*.jsonl.gz"))


def test_there_are_committed_exports() -> None:
    assert len(EXPORTS) >= 10, [str(p) for p in EXPORTS]


@pytest.mark.parametrize("export", EXPORTS, ids=[str(p.relative_to(RESULTS)) for p in EXPORTS])
def test_every_committed_run_is_on_the_pin(export: Path) -> None:
    pins = Counter((r["tags"].get("vlmrl.pin"), r["tags"].get("vlmrl.pin.user")) for r in read_records(export))
    assert pins and set(pins) == {(PIN_ID, "none")}, f"{export}: runs by (pin, user override) {dict(pins)}"
