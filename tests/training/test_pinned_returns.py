"""Speed-ups and refactors keep the numbers: a short run of each VLM arm (paper preset, seed 0,
30,000 steps, simulated VLM, no cache) gives the learning curve pinned here, bit for bit.

The digests were printed by the code that trained the committed study (commit 39291e8) and
again after the hybrid's per-step work was trimmed (frame features summed per channel, batched
cache commits, einsum distances); ``native_returns`` is the worker's own training path.

torch's BLAS (MKL) rounds differently on some CPUs (docs/development.md, "Same numbers on every
x86-64 CPU"), so the digests are pinned per set of CPU code paths (``core.provenance.cpu_paths``):
the Sapphire Rapids machine that first printed them, and the AVX512_ICL machines (an Intel one
and an AMD EPYC one train the same runs bit for bit). On other code paths the test has no
reference and skips, saying so.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json

import pytest

from vlmrl_cli.core.provenance import cpu_paths
from vlmrl_cli.training.config import RunConfig
from vlmrl_cli.training.presets import get_preset
from vlmrl_cli.training.trace import native_returns
from vlmrl_cli.vlm.config import VLMConfig

pytestmark = pytest.mark.slow  # trains

ARMS = ("hybrid", "hybrid-no-lock", "semantic")
# cpu code paths (numpy_simd, blas, torch) -> arm -> (episodes completed, sha256 of the JSON list
# of native returns, first 16 hex)
PINNED: dict[tuple[str, str, str], dict[str, tuple[int, str]]] = {
    ("X86_V3,X86_V4,AVX512_ICL,AVX512_SPR", "openblas SkylakeX", "AVX512"): {  # Sapphire Rapids, 2026-12-01
        "hybrid": (193, "26701034cd2f5a35"),
        "semantic": (179, "510ded1bb8db7f0e"),
        "hybrid-no-lock": (191, "1e745353bbe526d6"),
    },
    ("X86_V3,X86_V4,AVX512_ICL", "openblas SkylakeX", "AVX512"): {  # AMD EPYC, 2026-12-02
        "hybrid": (193, "ca501b4e47b564c5"),
        "semantic": (179, "4637d891cf9cc42a"),
        "hybrid-no-lock": (191, "1e745353bbe526d6"),
    },
}


def _pinned(arm: str) -> tuple[int, str]:
    paths = cpu_paths()
    key = (paths["numpy_simd"], paths["blas"], paths["torch"])
    if key not in PINNED:
        pytest.skip(f"no digest pinned for these CPU code paths {key}; add one printed by a known-good commit")
    return PINNED[key][arm]


@pytest.mark.parametrize("arm", ARMS)
def test_a_short_run_gives_the_pinned_learning_curve(arm: str) -> None:
    ppo = dataclasses.replace(get_preset("paper"), timesteps=30_000)
    cfg = RunConfig(arms=(arm,), seeds=(0,), preset="paper", ppo=ppo, workers=1, vlm=VLMConfig(use_cache=False))
    returns = native_returns(cfg.jobs()[0])
    digest = hashlib.sha256(json.dumps(returns).encode()).hexdigest()[:16]
    assert (len(returns), digest) == _pinned(arm)
