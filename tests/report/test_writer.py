"""report.writer.for_task: unset thresholds and window come from the task; given ones are kept."""

from __future__ import annotations

import pytest

from vlmrl_cli.report.writer import ReportConfig, for_task
from vlmrl_cli.tasks.registry import get_task

TASKS = ("mountain-car", "acrobot", "mountain-car-continuous")


@pytest.mark.parametrize("name", TASKS)
def test_unset_thresholds_and_window_are_the_tasks(name: str) -> None:
    task = get_task(name)
    cfg = for_task(ReportConfig(), task)
    assert cfg.thresholds == task.thresholds and cfg.window == task.window
    assert 1 <= cfg.min_episodes <= task.window


@pytest.mark.parametrize("name", TASKS)
@pytest.mark.parametrize("window", [1, 20, 100, 250])
def test_a_given_window_is_kept_even_when_it_equals_mountain_cars(name: str, window: int) -> None:
    # --window 100 on Acrobot used to be read as "left at the default" and became 20
    assert for_task(ReportConfig(window=window), get_task(name)).window == window


@pytest.mark.parametrize("name", TASKS)
def test_given_thresholds_are_kept_even_when_they_are_mountain_cars(name: str) -> None:
    given = (-190.0, -160.0, -130.0)
    assert for_task(ReportConfig(thresholds=given), get_task(name)).thresholds == given


def test_a_window_taken_from_the_task_caps_min_episodes_and_a_given_one_does_not() -> None:
    acrobot = get_task("acrobot")
    assert for_task(ReportConfig(min_episodes=50), acrobot).min_episodes == acrobot.window
    assert for_task(ReportConfig(window=100, min_episodes=50), acrobot).min_episodes == 50


def test_a_disagreement_states_the_papers_figure_without_our_seed_count() -> None:
    from vlmrl_cli.report.markdown import paper_disagreement

    cell = {"metric": "reliability", "arm": "hybrid", "value": 0.0, "ci_low": 0.0, "ci_high": 0.66, "n": 2,
            "n_reached": 0, "paper": 1.0, "note": ""}
    line = paper_disagreement("Final reliability (seeds reaching -130)", "hybrid", cell)
    assert line == ("- Final reliability (seeds reaching -130), hybrid: paper 100%, ours 0% [0%, 66%] (0/2) "
                    "(outside our CI).")
    assert "(2/2)" not in line  # the paper's 100% is its own figure, not 2 of our 2 seeds
    inside = {**cell, "value": 0.9, "ci_low": 0.6, "ci_high": 1.0, "n_reached": 2}
    assert paper_disagreement("Final reliability", "hybrid", inside) is None
