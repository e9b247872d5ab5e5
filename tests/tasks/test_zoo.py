"""The zoo's score table agrees with each built-in task's cited ``zoo_reference``."""

from __future__ import annotations

import pytest

from vlmrl_cli.tasks.registry import BUILTIN, get_task
from vlmrl_cli.tasks.zoo import ZOO_PPO


@pytest.mark.parametrize("name", list(BUILTIN))
def test_every_builtin_task_has_its_cited_zoo_score(name: str) -> None:
    task = get_task(name)
    if task.env_id not in ZOO_PPO:  # the zoo publishes no PPO score for it: the reference says so
        assert "no PPO row" in task.zoo_reference
        return
    score = ZOO_PPO[task.env_id]
    assert f"PPO {task.env_id}: {score.mean:.3f} +/- {score.std:.3f} ({score.budget} steps)" in task.zoo_reference
