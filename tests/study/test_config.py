"""The study's grid: regimes from flags, file or defaults; VLM variants deduplicated by their knobs."""

from __future__ import annotations

import pytest

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.study.config import build_study, choose_regimes, study_section


def test_default_regimes_are_paper_calibrated_and_hard() -> None:
    regimes, notes = choose_regimes([], None)
    assert list(regimes) == ["paper", "paper-calibrated", "hard"] and notes == []
    assert regimes["hard"] == {"preset": "paper", "ppo.normalize_obs": False, "ppo.normalize_reward": False}


def test_default_regimes_skip_a_missing_preset_with_a_note(monkeypatch: pytest.MonkeyPatch) -> None:
    from vlmrl_cli.training import presets

    monkeypatch.delitem(presets.PRESETS, "paper-calibrated")
    regimes, notes = choose_regimes([], None)
    assert list(regimes) == ["paper", "hard"]
    assert len(notes) == 1 and "paper-calibrated" in notes[0] and "vlmrl calibrate" in notes[0]


def test_file_regimes_and_variants() -> None:
    section = study_section({"regimes": {"a": "smoke", "b": {"preset": "smoke", "ppo": {"normalize_obs": False}}}})
    regimes, _ = choose_regimes([], section["regimes"])
    cfg = build_study([], regimes, profiles=["ideal", "default"], flickers=[0.1, 0.5])
    assert [r.id for r in cfg.regimes] == ["a", "b"] and cfg.vlm_regime == "a"
    assert not cfg.regimes[1].run.ppo_config.normalize_obs
    # profile default and flicker 0.1 are the same knobs: one variant, both names
    assert [v.id for v in cfg.variants] == ["profile ideal", "profile default = flicker 0.1", "flicker 0.5"]
    assert all(v.run.arms == ("hybrid",) for v in cfg.variants)
    assert cfg.variants[0].run.vlm.sim.patch_px == 1
    assert cfg.variants[1].run.jobs()[0].config_hash == next(
        j for j in cfg.regimes[0].run.jobs() if j.arm.name == "hybrid").config_hash


@pytest.mark.parametrize("raw", [{"regimes": {"a": 3}}, {"regimez": {}}, {"flickers": ["x"]}])
def test_bad_study_tables(raw: dict) -> None:  # type: ignore[type-arg]
    with pytest.raises(BadInput):
        study_section(raw)
