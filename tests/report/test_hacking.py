"""report.hacking: the hovering diagnostic is MountainCar's; other tasks' reports say it does not apply."""

from __future__ import annotations

import pandas as pd

from vlmrl_cli.report import hacking
from vlmrl_cli.tasks.registry import get_task


def _frame() -> pd.DataFrame:
    per_seed = pd.DataFrame({"arm": ["hybrid", "baseline"], "hover_fraction": [float("nan")] * 2,
                             "dwell_right_steps": [float("nan")] * 2, "shaped_gap": [3.0, 0.0]})
    episodes = pd.DataFrame({"arm": ["hybrid", "baseline"], "length": [80, 90]})
    return hacking.hacking_frame(per_seed, episodes, 0.95, timeout=500)


def test_a_task_without_the_diagnostic_is_not_told_its_runs_predate_it() -> None:
    text = hacking.hacking_markdown(_frame(), hover=False)
    assert "no diagnostic for this task" in text and "predate" not in text


def test_runs_of_a_task_with_the_diagnostic_that_lack_it_predate_it() -> None:
    assert "predate the diagnostic" in hacking.hacking_markdown(_frame(), hover=True)


def test_the_definition_names_mountain_cars_track_only_where_it_applies() -> None:
    assert "x = 0.3" in hacking.definition(0.3) and "x = 0.45" in hacking.definition(0.45)
    assert "x = " not in hacking.definition(None)
    assert not get_task("acrobot").hover_diagnostic and get_task("mountain-car").hover_diagnostic
