"""Speed-ups, refactors and other CPUs keep the numbers: a short run of each arm (paper preset,
seed 0, 50,000 steps, simulated VLM, no cache) gives the learning curve pinned here, bit for bit.

One table, no per-CPU keys: the numeric pin (``core.numeric_pin``, applied by the repository's
conftest before torch loads) makes every x86-64-v3 CPU compute the same path, so a machine
whose digests differ fails here and prints its CPU, instead of skipping. The digests were
printed on the pinned path by an AMD EPYC (numpy ``X86_V3,X86_V4,AVX512_ICL``, OpenBLAS
SkylakeX, torch run at ``AVX2``) on 2026-12-03, with Adam's multi-tensor update
(``training.model.OPTIMIZER_KWARGS``); ``test_cpu_paths.py`` shows that the other
code paths this machine can be forced onto give them too, and that without the pin they move.
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
from vlmrl_cli.training.trace import native_returns
from vlmrl_cli.vlm.config import VLMConfig

pytestmark = pytest.mark.slow  # trains

# Long enough for the unpinned path to part from the pinned one (plain PPO: at episode 185, about
# 33,000 steps, on this machine), so that the table fails without the pin.
STEPS = 50_000
#: arm -> (episodes completed, sha256 of the JSON list of native returns, first 16 hex)
PINNED: dict[str, tuple[int, str]] = {
    "baseline": (317, "80bd6008a9a0c8b2"),
    "hybrid": (360, "d7883a803a0580b9"),
    "hybrid-no-lock": (356, "e1fb4a6578cb53ad"),
    "semantic": (312, "fc2a4ce4596e9318"),
}


def digest(returns: list[float]) -> tuple[int, str]:
    """What ``PINNED`` holds for a learning curve."""
    return len(returns), hashlib.sha256(json.dumps(returns).encode()).hexdigest()[:16]


def short_run(arm: str, steps: int = STEPS) -> list[float]:
    ppo = dataclasses.replace(preset_of(get_task("mountain-car"), "paper"), timesteps=steps)
    cfg = RunConfig(arms=(arm,), seeds=(0,), preset="paper", ppo=ppo, workers=1, vlm=VLMConfig(use_cache=False))
    return native_returns(cfg.jobs()[0])


def test_this_process_computes_on_the_pinned_path() -> None:
    state = pin_state()
    assert state.pinned, f"the test process is off the numeric pin: {state.values} (user: {dict(state.user)})"
    assert cpu_paths()["torch"] == "AVX2"


@pytest.mark.parametrize("arm", list(PINNED))
def test_a_short_run_gives_the_pinned_learning_curve(arm: str) -> None:
    got = digest(short_run(arm))
    assert got == PINNED[arm], (
        f"{arm}: {got} is not the pinned {PINNED[arm]} on this machine: CPU {pin_record()['cpu.model']}, "
        f"code paths {cpu_paths()}, pin {pin_record()['pin.env']} (user: {pin_record()['pin.user']})")
