"""The hybrid's pinned numbers on forced numpy and OpenBLAS paths (its shaping's own arithmetic),
and the pin removed: the numbers move, so ``test_pinned_returns.py`` can fail (a file of its own so
that the suite's two workers share these runs with ``test_cpu_paths.py``)."""

from __future__ import annotations

import os

import pytest

from tests.training.cpu_probe import OVERRIDES, pinned_reference, trace

pytestmark = pytest.mark.slow  # trains


@pytest.mark.parametrize("override", ["numpy-baseline", "openblas-prescott"])
def test_the_pinned_hybrid_holds_on_a_forced_path(override: str) -> None:
    got = trace("hybrid", OVERRIDES[override], pinned=True)
    assert (tuple(got["digest"]), got["weights"]) == pinned_reference("hybrid"), (
        f"hybrid under {OVERRIDES[override]} on {got['paths']}")


def test_without_the_pin_the_weights_move() -> None:
    """Unpinned, the trained weights part from the pinned ones (the returns follow tens of
    thousands of steps later: about 33,000 for plain PPO here, inside the table's 50,000, whose
    weights digest catches it in any case), and the CPU's capability moves them too."""
    _, pinned_weights = pinned_reference("baseline")
    unpinned = trace("baseline", {}, pinned=False)
    assert unpinned["paths"]["torch"] != "AVX2" or os.environ.get("ATEN_CPU_CAPABILITY") == "avx2"
    assert unpinned["weights"] != pinned_weights  # test_pinned_returns fails without the pin
    other = trace("baseline", {"ATEN_CPU_CAPABILITY": "default"}, pinned=False)
    assert other["weights"] != unpinned["weights"]  # and unpinned, the CPU's capability moves them
