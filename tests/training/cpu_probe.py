"""Train a short run in a fresh process under forced CPU code paths (the libraries read the
variables once, at load), for ``test_cpu_paths*.py``.

A forced path is compared with the pinned path at ``FORCED_STEPS`` steps, bit for bit in the
trained weights (``training.trace.weights_digest``) as well as in the returns: two numeric paths
that round one operation differently part in the weights at the first update that uses it, while
their episodes part only tens of thousands of steps later (unpinned plain PPO here: weights
differ at 10,240 steps, returns identical until about 33,000). So a short run with the weights
checks a path as a 50,000-step run of returns alone did, in a fifth of the time.
"""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys

from vlmrl_cli.core.numeric_pin import PIN_VARIABLES, cpuinfo_fields, read_cpuinfo

#: Steps of a forced-path run: 40 PPO updates of the paper preset.
FORCED_STEPS = 10_240

_PROBE = """
import os, sys
if os.environ.get("PROBE_PIN") == "1":
    from vlmrl_cli.core.numeric_pin import apply
    apply(warn=False)
import json, torch
torch.set_num_threads(1)
from tests.training.test_pinned_returns import digest, short_trace
from vlmrl_cli.core.provenance import cpu_paths
trace = short_trace(sys.argv[1], int(sys.argv[2]))
print(json.dumps({"paths": cpu_paths(), "digest": digest(trace.native_returns), "weights": trace.weights_sha256}))
"""
_NUMERIC_VARS = (*PIN_VARIABLES, "NPY_DISABLE_CPU_FEATURES", "OPENBLAS_CORETYPE",
                 "MKL_ENABLE_INSTRUCTIONS")


def trace(arm: str, env: dict[str, str], pinned: bool, steps: int = FORCED_STEPS) -> dict:  # type: ignore[type-arg]
    """``arm``'s paths, returns digest and weights digest after ``steps`` steps in a fresh
    process: the pin applied (``pinned``) or removed, then ``env`` laid over the environment."""
    clean = {k: v for k, v in os.environ.items() if k not in _NUMERIC_VARS}  # this process's pin removed
    full = clean | env | {"PROBE_PIN": "1" if pinned else "0", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", _PROBE, arm, str(steps)], env=full, capture_output=True, text=True,
                         check=True, timeout=600, cwd=os.path.dirname(os.path.dirname(os.path.dirname(__file__))))
    return json.loads(out.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


@functools.cache
def pinned_reference(arm: str) -> tuple[tuple[int, str], str]:
    """``arm`` on the pinned path with no override, ``FORCED_STEPS`` steps, trained in this
    process (once per process; the test process computes on the pinned path, which
    ``test_pinned_returns.py`` checks): its returns digest and weights digest, what a forced path
    must give. It is the run ``trace`` makes with ``pinned=True`` and no override, without a
    fresh interpreter's 4-5 s of start-up."""
    from tests.training.test_pinned_returns import digest, short_trace

    got = short_trace(arm, FORCED_STEPS)
    return digest(got.native_returns), got.weights_sha256


def cpu_flags(cpuinfo: str = "/proc/cpuinfo") -> frozenset[str]:
    """The first CPU's feature flags (empty where the file is missing or has no flags line)."""
    return frozenset(cpuinfo_fields(read_cpuinfo(cpuinfo)).get("flags", "").split())


# what torch's avx512 kernels need (aten/src/ATen/native/DispatchStub.cpp: AVX512F, BW, VL, DQ)
AVX512 = frozenset({"avx512f", "avx512bw", "avx512vl", "avx512dq"})
ALL_NUMPY_TARGETS = "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"
OVERRIDES = {
    "mkl-avx2": {"MKL_ENABLE_INSTRUCTIONS": "AVX2"},
    "mkl-sse4_2": {"MKL_ENABLE_INSTRUCTIONS": "SSE4_2"},
    "aten-avx512": {"ATEN_CPU_CAPABILITY": "avx512"},
    "onednn-sse41": {"ONEDNN_MAX_CPU_ISA": "SSE41"},
    "numpy-baseline": {"NPY_DISABLE_CPU_FEATURES": ALL_NUMPY_TARGETS},
    "openblas-prescott": {"OPENBLAS_CORETYPE": "Prescott"},
}
# an override that only a CPU with these flags can run (forcing it elsewhere dies with SIGILL)
NEEDS = {"aten-avx512": AVX512}
