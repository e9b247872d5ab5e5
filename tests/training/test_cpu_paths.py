"""The pinned digests hold on every code path this machine can be forced onto, and without the
pin they move (so ``test_pinned_returns.py`` can fail).

Each run is a fresh subprocess (the libraries read the variables once, at load): the pin applied
as ``vlmrl`` applies it, then one override that makes a library pick other kernels (an ISA limit,
as an older or another vendor's CPU would have). A variable of the pin itself given by the user
wins over the pin (``ATEN_CPU_CAPABILITY=avx512``: the capability this CPU picks unpinned).
Measured here (AMD EPYC, 2026-12-03): unpinned, plain PPO's curve moves with the pin's MKL branch
and under ``ATEN_CPU_CAPABILITY=default``; ``MKL_ENABLE_INSTRUCTIONS`` moved nothing even
unpinned on this CPU, so it simulates little here and is kept for Intel machines.
"""

from __future__ import annotations

import pytest

from tests.training.cpu_probe import NEEDS, OVERRIDES, cpu_flags, trace
from tests.training.test_pinned_returns import PINNED

pytestmark = pytest.mark.slow  # trains


@pytest.mark.parametrize("override", list(OVERRIDES))
def test_the_pinned_baseline_holds_on_a_forced_path(override: str) -> None:
    missing = NEEDS.get(override, frozenset()) - cpu_flags()
    if missing:
        pytest.skip(f"{override} needs CPU flags this machine lacks: {', '.join(sorted(missing))}")
    got = trace("baseline", OVERRIDES[override], pinned=True)
    assert tuple(got["digest"]) == PINNED["baseline"], f"baseline under {OVERRIDES[override]} on {got['paths']}"
