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

import json
import os
import subprocess
import sys

import pytest

from tests.training.test_pinned_returns import PINNED, STEPS
from vlmrl_cli.core.numeric_pin import APPLIED_MARK, PIN, USER_MARK

pytestmark = pytest.mark.slow  # trains

_PROBE = """
import os, sys
if os.environ.get("PROBE_PIN") == "1":
    from vlmrl_cli.core.numeric_pin import apply
    apply(warn=False)
import json, torch
torch.set_num_threads(1)
from tests.training.test_pinned_returns import digest, short_run
from vlmrl_cli.core.provenance import cpu_paths
print(json.dumps({"paths": cpu_paths(), "digest": digest(short_run(sys.argv[1], int(sys.argv[2])))}))
"""
_NUMERIC_VARS = (*PIN, USER_MARK, APPLIED_MARK, "NPY_DISABLE_CPU_FEATURES", "OPENBLAS_CORETYPE",
                 "MKL_ENABLE_INSTRUCTIONS")


def _trace(arm: str, env: dict[str, str], pinned: bool) -> dict:  # type: ignore[type-arg]
    clean = {k: v for k, v in os.environ.items() if k not in _NUMERIC_VARS}  # this process's pin removed
    full = clean | env | {"PROBE_PIN": "1" if pinned else "0", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", _PROBE, arm, str(STEPS)], env=full, capture_output=True, text=True,
                         check=True, timeout=600, cwd=os.path.dirname(os.path.dirname(os.path.dirname(__file__))))
    return json.loads(out.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


ALL_NUMPY_TARGETS = "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"
OVERRIDES = {
    "mkl-avx2": {"MKL_ENABLE_INSTRUCTIONS": "AVX2"},
    "mkl-sse4_2": {"MKL_ENABLE_INSTRUCTIONS": "SSE4_2"},
    "aten-avx512": {"ATEN_CPU_CAPABILITY": "avx512"},
    "onednn-sse41": {"ONEDNN_MAX_CPU_ISA": "SSE41"},
    "numpy-baseline": {"NPY_DISABLE_CPU_FEATURES": ALL_NUMPY_TARGETS},
    "openblas-prescott": {"OPENBLAS_CORETYPE": "Prescott"},
}
CASES = [("baseline", name) for name in OVERRIDES] + [("hybrid", "numpy-baseline"), ("hybrid", "openblas-prescott")]


@pytest.mark.parametrize(("arm", "override"), CASES)
def test_the_pinned_digest_holds_on_a_forced_path(arm: str, override: str) -> None:
    got = _trace(arm, OVERRIDES[override], pinned=True)
    assert tuple(got["digest"]) == PINNED[arm], f"{arm} under {OVERRIDES[override]} on paths {got['paths']}"


def test_without_the_pin_the_digests_move() -> None:
    unpinned = _trace("baseline", {}, pinned=False)
    assert unpinned["paths"]["torch"] != "AVX2" or os.environ.get("ATEN_CPU_CAPABILITY") == "avx2"
    assert tuple(unpinned["digest"]) != PINNED["baseline"]  # test_pinned_returns fails without the pin
    other = _trace("baseline", {"ATEN_CPU_CAPABILITY": "default"}, pinned=False)
    assert other["digest"] != unpinned["digest"]  # and unpinned, the CPU's capability moves the curve
