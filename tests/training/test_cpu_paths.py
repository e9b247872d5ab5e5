"""The shaped arms train the same agent whatever SIMD and BLAS code the CPU runs.

Before the fix (float32 features through OpenBLAS ``sgemv``), on an AVX-512 machine,
``OPENBLAS_CORETYPE=Haswell`` made seed 0 of the paper preset diverge from the default
(SkylakeX kernel) at episode 234 (~34,000 steps) for hybrid and at episode 172 (~28,000
steps) for semantic (``scripts/cpu_paths.py``). These runs are 50,000 steps long. Each runs
in a fresh subprocess, because numpy and OpenBLAS read the variables once, at import.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from vlmrl_cli.core.provenance import cpu_paths

pytestmark = pytest.mark.slow  # trains, starts Ray or servers, or builds the wheel

STEPS = 50_000

_PROBE = """
import dataclasses, json, sys, torch
torch.set_num_threads(1)
from vlmrl_cli.core.provenance import cpu_paths
from vlmrl_cli.training.config import RunConfig
from vlmrl_cli.training.presets import get_preset
from vlmrl_cli.training.trace import native_returns
from vlmrl_cli.vlm.config import VLMConfig
ppo = dataclasses.replace(get_preset("paper"), timesteps=int(sys.argv[2]))
cfg = RunConfig(arms=(sys.argv[1],), seeds=(0,), preset="paper", ppo=ppo, workers=1, vlm=VLMConfig(use_cache=False))
print(json.dumps({"paths": cpu_paths(), "returns": native_returns(cfg.jobs()[0])}))
"""


def _trace(arm: str, env: dict[str, str]) -> dict:  # type: ignore[type-arg]
    full = {k: v for k, v in os.environ.items() if k not in ("NPY_DISABLE_CPU_FEATURES", "OPENBLAS_CORETYPE")}
    out = subprocess.run([sys.executable, "-c", _PROBE, arm, str(STEPS)], env=full | env, capture_output=True,
                         text=True, check=True, timeout=600)
    return json.loads(out.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


@pytest.mark.parametrize("arm", ["hybrid", "semantic"])
def test_forced_numpy_and_blas_paths_train_the_same_agent(arm: str) -> None:
    forced = {"OPENBLAS_CORETYPE": "Prescott"}
    simd = cpu_paths()["numpy_simd"]  # the dispatch targets this CPU runs, comma-separated
    if simd not in ("baseline", "unknown"):
        forced["NPY_DISABLE_CPU_FEATURES"] = simd.replace(",", " ")
    default, other = _trace(arm, {}), _trace(arm, forced)
    assert other["paths"] != default["paths"]  # the variables took effect
    assert len(default["returns"]) > 300
    assert other["returns"] == default["returns"]
