"""Measure a uniformly random policy's detached evaluation score on every built-in task (or the
tasks named), 200 episodes from seed 0: the figures stored as each ``Task.random_score``.

    python scripts/random_scores.py [TASK ...]
"""

from __future__ import annotations

import sys

from vlmrl_cli.tasks.registry import BUILTIN, get_task
from vlmrl_cli.training.random_policy import EPISODES, SEED, random_policy_score


def main(names: list[str]) -> None:
    for name in names or list(BUILTIN):
        task = get_task(name)
        r = random_policy_score(task, EPISODES, SEED)
        print(f"{name} ({task.env_id}): mean return {r.mean_return:.6f} over {EPISODES} episodes from seed {SEED} "
              f"(success {r.success_rate:.3f}, mean length {r.mean_length:.1f})", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
