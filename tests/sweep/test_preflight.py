"""A sweep's one check before anything exists: VLM arms need a VLM that can answer them."""

from __future__ import annotations

from pathlib import Path

import pytest

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.sweep.preflight import preflight
from vlmrl_cli.training.config import RunConfig
from vlmrl_cli.vlm.config import VLMConfig


def test_the_paper_transcript_cannot_train_a_vlm_arm_but_the_baseline_needs_no_vlm(tmp_path: Path) -> None:
    replay = VLMConfig(backend="replay", use_cache=False)
    with pytest.raises(BadInput, match=r"cannot answer 600 of the 601"):
        preflight(RunConfig(arms=("hybrid",), seeds=(0,), vlm=replay))
    preflight(RunConfig(arms=("baseline",), seeds=(0,), vlm=replay))


def test_a_bad_cache_path_is_refused_only_when_an_arm_asks_the_vlm(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    vlm = VLMConfig(cache_path=tmp_path / "f" / "c.sqlite")
    with pytest.raises(BadInput, match="response cache"):
        preflight(RunConfig(arms=("baseline", "semantic"), seeds=(0,), vlm=vlm))
    preflight(RunConfig(arms=("baseline", "kinematic"), seeds=(0,), vlm=vlm))
