"""Speed-ups, refactors and other CPUs keep the numbers: a short run of each arm (paper preset,
seed 0, 50,000 or 10,240 steps, simulated VLM, no cache) gives the learning curve and the trained
weights pinned here, bit for bit.

One table, no per-CPU keys: the numeric pin (``core.numeric_pin``, applied by the repository's
conftest before torch loads) makes every x86-64-v3 CPU compute the same path, so a machine
whose digests differ fails here and prints its CPU, instead of skipping. The digests were
printed on the pinned path by an AMD EPYC (numpy ``X86_V3,X86_V4,AVX512_ICL``, OpenBLAS
SkylakeX, torch run at ``AVX2``) on 2026-12-03, with Adam's multi-tensor update
(``training.model.OPTIMIZER_KWARGS``). The digests of the trained weights
(``training.trace.weights_digest``), which part at the first update computed another way, were
added on 2026-12-07 by an AMD EPYC without AVX-512 (Zen 3; numpy ``X86_V3``, OpenBLAS Haswell,
torch at ``AVX2``), where the 50,000-step returns digests held as printed on 2026-12-03.
``test_cpu_paths.py`` shows that the other code paths this machine can be forced onto give the
same numbers, and that without the pin they move.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json

import pytest

from vlmrl_cli.core.numeric_pin import pin_record, pin_state
from vlmrl_cli.core.provenance import cpu_paths
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.training.config import RunConfig
from vlmrl_cli.training.presets import preset_of
from vlmrl_cli.training.trace import TrainTrace, train_trace
from vlmrl_cli.vlm.config import VLMConfig

pytestmark = pytest.mark.slow  # trains

# Long enough for the unpinned returns to part from the pinned ones (plain PPO: at episode 185, about
# 33,000 steps, on this machine), so that the returns alone fail without the pin; the weights part at
# once. Episodes reach the flag well before the end, so success paths (lock, cache) run too.
STEPS = 50_000
SHORT_STEPS = 10_240  # 40 PPO updates of the paper preset
#: arm -> (steps, episodes completed, sha256 of the JSON list of native returns, sha256 of the
#: trained weights; first 16 hex each). Plain PPO and the hybrid run the full ``STEPS`` (the
#: hybrid's lock and prototype cache see the flag); hybrid-no-lock and semantic, which only drop
#: terms of the hybrid's shaping, are held to their weights after ``SHORT_STEPS``, which part at
#: the first update computed another way (these two digests printed on the Zen 3, 2026-12-07).
PINNED: dict[str, tuple[int, int, str, str]] = {
    "baseline": (STEPS, 317, "80bd6008a9a0c8b2", "43a75d25c55468ee"),
    "hybrid": (STEPS, 360, "d7883a803a0580b9", "764a55c9ba8f5fa5"),
    "hybrid-no-lock": (SHORT_STEPS, 49, "4f0ddefe1e934564", "62958bcb9df304ca"),
    "semantic": (SHORT_STEPS, 48, "50832be814581adc", "b61efe94d2008d26"),
}


def digest(returns: list[float]) -> tuple[int, str]:
    """What ``PINNED`` holds for a learning curve."""
    return len(returns), hashlib.sha256(json.dumps(returns).encode()).hexdigest()[:16]


def short_trace(arm: str, steps: int = STEPS) -> TrainTrace:
    """``arm`` trained for ``steps`` steps (paper preset, seed 0, no VLM cache), in this process."""
    ppo = dataclasses.replace(preset_of(get_task("mountain-car"), "paper"), timesteps=steps)
    cfg = RunConfig(arms=(arm,), seeds=(0,), preset="paper", ppo=ppo, workers=1, vlm=VLMConfig(use_cache=False))
    return train_trace(cfg.jobs()[0])


def test_this_process_computes_on_the_pinned_path() -> None:
    state = pin_state()
    assert state.pinned, f"the test process is off the numeric pin: {state.values} (user: {dict(state.user)})"
    assert cpu_paths()["torch"] == "AVX2"


@pytest.mark.parametrize("arm", list(PINNED))
def test_a_short_run_gives_the_pinned_learning_curve(arm: str) -> None:
    steps = PINNED[arm][0]
    trace = short_trace(arm, steps)
    got = (steps, *digest(trace.native_returns), trace.weights_sha256[:16])
    assert got == PINNED[arm], (
        f"{arm}: {got} is not the pinned {PINNED[arm]} on this machine: CPU {pin_record()['cpu.model']}, "
        f"code paths {cpu_paths()}, pin {pin_record()['pin.env']} (user: {pin_record()['pin.user']})")
