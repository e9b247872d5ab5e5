"""The hybrid's pinned digest on forced numpy and OpenBLAS paths (its shaping's own arithmetic),
and the pin removed: the digests move, so ``test_pinned_returns.py`` can fail (a file of its own so
that the suite's two workers share these runs with ``test_cpu_paths.py``)."""

from __future__ import annotations

import os

import pytest

from tests.training.cpu_probe import OVERRIDES, trace
from tests.training.test_pinned_returns import PINNED

pytestmark = pytest.mark.slow  # trains


@pytest.mark.parametrize("override", ["numpy-baseline", "openblas-prescott"])
def test_the_pinned_hybrid_holds_on_a_forced_path(override: str) -> None:
    got = trace("hybrid", OVERRIDES[override], pinned=True)
    assert tuple(got["digest"]) == PINNED["hybrid"], f"hybrid under {OVERRIDES[override]} on {got['paths']}"


def test_without_the_pin_the_digests_move() -> None:
    unpinned = trace("baseline", {}, pinned=False)
    assert unpinned["paths"]["torch"] != "AVX2" or os.environ.get("ATEN_CPU_CAPABILITY") == "avx2"
    assert tuple(unpinned["digest"]) != PINNED["baseline"]  # test_pinned_returns fails without the pin
    other = trace("baseline", {"ATEN_CPU_CAPABILITY": "default"}, pinned=False)
    assert other["digest"] != unpinned["digest"]  # and unpinned, the CPU's capability moves the curve
