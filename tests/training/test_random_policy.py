"""A random policy's score, as stored on each built-in task, is what the stored command measures."""

from __future__ import annotations

import pytest

from vlmrl_cli.tasks.base import RANDOM_SCORE_COMMAND
from vlmrl_cli.tasks.registry import BUILTIN, get_task
from vlmrl_cli.training.random_policy import EPISODES, SEED, random_policy_score


def _check(name: str) -> None:
    task = get_task(name)
    stored = task.random_score
    assert stored is not None and stored.command == RANDOM_SCORE_COMMAND
    assert (stored.episodes, stored.seed) == (EPISODES, SEED) and stored.episodes >= 200
    measured = random_policy_score(task, stored.episodes, stored.seed).mean_return
    assert measured == pytest.approx(stored.mean, abs=5e-6)


def test_mountain_cars_random_score_is_measured_again() -> None:
    _check("mountain-car")


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in BUILTIN if n != "mountain-car"])
def test_every_builtin_tasks_random_score_is_measured_again(name: str) -> None:
    _check(name)


def test_the_same_seed_gives_the_same_random_episodes() -> None:
    task = get_task("acrobot")
    a, b = random_policy_score(task, 2, 3), random_policy_score(task, 2, 3)
    assert a.returns.tolist() == b.returns.tolist()
