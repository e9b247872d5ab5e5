"""Calibration regimes: the grid, its target, and the tasks it can score."""

from __future__ import annotations

import pytest

from vlmrl_cli.analysis.learning_profile import paper_baseline
from vlmrl_cli.calibration.regimes import build_regimes, calibrate_config
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.paper import REPORTED
from vlmrl_cli.tasks.registry import get_task


def test_the_default_grid_builds_baseline_regimes_of_mountain_car() -> None:
    regimes = build_regimes([], {})
    assert regimes and all(r.run.arms == ("baseline",) and r.run.task == "mountain-car" for r in regimes)
    cfg = calibrate_config(regimes)
    assert cfg.target == paper_baseline(REPORTED) and cfg.window == 100


@pytest.mark.parametrize("name", ["acrobot", "mountain-car-continuous"])
def test_another_task_calibrates_its_own_grid_against_the_scaled_paper_profile(name: str) -> None:
    task = get_task(name)
    regimes = build_regimes([{"task": name}], {})
    assert [dict(r.overrides) for r in regimes] == [dict(p) for p in task.calibration]
    assert all(r.run.task == name and r.run.arms == ("baseline",) for r in regimes)
    cfg = calibrate_config(regimes)
    paper = paper_baseline(REPORTED)
    assert cfg.target.thresholds == task.thresholds and cfg.window == task.window
    assert cfg.target.reliability == paper.reliability
    # each threshold at the paper's fraction of the budget (three thresholds each: no interpolation)
    for mine, theirs in zip(cfg.target.steps, paper.steps, strict=True):
        assert mine == pytest.approx(theirs / 300_000 * cfg.base.budget)


def test_a_grid_over_two_tasks_is_refused() -> None:
    regimes = build_regimes([], {"task": ["mountain-car", "acrobot"], "preset": ["smoke"]})
    with pytest.raises(BadInput, match="calibrate one task at a time"):
        calibrate_config(regimes)


def test_a_preset_the_default_grid_would_replace_is_refused_with_the_grids_values() -> None:
    # DoorKey's default grid is a list of presets: `--preset smoke` would be dropped silently
    with pytest.raises(BadInput, match=r"preset is set by you and by the task's default calibration grid.*"
                                       r"\"sb3-default-100k\".*--grid preset=A,B"):
        build_regimes([{"task": "minigrid-doorkey"}, {}, {"preset": "smoke"}], {})


def test_a_key_set_both_by_set_and_by_grid_is_refused() -> None:
    with pytest.raises(BadInput, match=r"ppo.learning_rate is set by you and by --grid \(ppo.learning_rate=0.0001"):
        build_regimes([{}, {"ppo": {"learning_rate": 3e-4}}, {}], {"ppo.learning_rate": [1e-4, 2e-4]})


def test_keys_the_grid_does_not_set_still_apply_to_every_regime() -> None:
    # MountainCar's default grid sets no preset, so `--preset smoke` is the base of every regime
    regimes = build_regimes([{}, {"ppo": {"gamma": 0.98}}, {"preset": "smoke"}], {})
    assert all(r.run.preset == "smoke" and r.run.ppo is not None and r.run.ppo.gamma == 0.98 for r in regimes)
    regimes = build_regimes([{"preset": "smoke"}], {"ppo.learning_rate": [1e-4, 2e-4]})
    assert [r.run.ppo.learning_rate if r.run.ppo else None for r in regimes] == [1e-4, 2e-4]
