"""The score of a uniformly random policy on a task (``tasks.base.RandomScore``, the 0 of `vlmrl
compare`), measured by ``scripts/random_scores.py``."""

from __future__ import annotations

import copy

from vlmrl_cli.tasks.base import Task
from vlmrl_cli.training.evaluation import EvalResult, evaluate_detached

#: The measurement stored on the built-in tasks.
EPISODES, SEED = 200, 0


def random_policy_score(task: Task, episodes: int = EPISODES, seed: int = SEED) -> EvalResult:
    """``evaluate_detached`` under uniform random actions from the action space seeded ``seed``."""
    env = task.make_env()
    space = copy.deepcopy(env.action_space)
    env.close()
    space.seed(seed)
    return evaluate_detached(lambda _obs: space.sample(), episodes, seed, task)
