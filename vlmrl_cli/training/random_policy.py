"""The score of a uniformly random policy on a task: the fixed 0 of ``vlmrl compare``'s
normalisation (``tasks.base.RandomScore``), measured by the task's own detached evaluation.

Measured by ``python scripts/random_scores.py`` (every built-in task, 200 episodes, seed 0); the
figures it printed are stored on each ``Task`` with that command, and a test measures them again.
"""

from __future__ import annotations

import copy
from typing import Any

from vlmrl_cli.tasks.base import Task
from vlmrl_cli.training.evaluation import EvalResult, evaluate_detached

#: The measurement stored on the built-in tasks.
EPISODES, SEED = 200, 0


def random_policy_score(task: Task, episodes: int = EPISODES, seed: int = SEED) -> EvalResult:
    """``episodes`` detached evaluation episodes of ``task`` (``evaluate_detached``: episode ``i``
    resets with ``seed + i``, the task's own success rule) under uniform random actions drawn from
    the env's action space, itself seeded with ``seed``: the same figures on every call.

    Example:
        >>> from vlmrl_cli.tasks.registry import get_task
        >>> random_policy_score(get_task("mountain-car"), episodes=3).mean_return
        -200.0
    """
    env = task.make_env()
    space = copy.deepcopy(env.action_space)
    env.close()
    space.seed(seed)

    def act(_obs: Any) -> Any:
        return space.sample()

    return evaluate_detached(act, episodes, seed, task)
