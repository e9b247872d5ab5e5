"""Calibration regimes: the grid, and the tasks it can score."""

from __future__ import annotations

import pytest

from vlmrl_cli.calibration.regimes import build_regimes
from vlmrl_cli.core.errors import BadInput


def test_the_default_grid_builds_baseline_regimes_of_mountain_car() -> None:
    regimes = build_regimes([], {})
    assert regimes and all(r.run.arms == ("baseline",) and r.run.task == "mountain-car" for r in regimes)


def test_another_task_is_refused_until_its_scoring_exists() -> None:
    with pytest.raises(BadInput, match="task 'acrobot': calibrate and study score against MountainCar"):
        build_regimes([{"task": "acrobot"}], {})
