"""Detached evaluation: the trained policy alone, no VLM, no shaping, no rendering."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vlmrl_cli.shaping.hacking import HoverSummary, summarize_hovering
from vlmrl_cli.tasks.base import Task

Policy = Callable[[np.ndarray], Any]  # an observation -> an action (an int for discrete actions)


@dataclass(frozen=True)
class EvalResult:
    """Per-episode figures of a detached evaluation, each shape (episodes,).

    ``positions``: one array of shape ``(length_i,)`` per episode, the task's position after each
    step (for the hovering diagnostic; empty when not recorded), ``hover_from`` where hovering
    starts (``Task.hover``).
    """

    returns: np.ndarray
    lengths: np.ndarray
    successes: np.ndarray
    positions: tuple[np.ndarray, ...] = field(default=())
    hover_from: float | None = None

    @property
    def success_rate(self) -> float:
        return float(self.successes.mean())

    @property
    def mean_length(self) -> float:
        return float(self.lengths.mean())

    @property
    def mean_return(self) -> float:
        return float(self.returns.mean())

    @property
    def hovering(self) -> HoverSummary:
        """Hover fraction and dwell past ``hover_from`` (see ``shaping.hacking``); NaN without positions."""
        if not self.positions or self.hover_from is None:
            return HoverSummary(float("nan"), float("nan"), 0)
        return summarize_hovering(self.positions, self.successes > 0.5, self.hover_from)


def evaluate_detached(policy: Policy, episodes: int, seed: int, task: Task) -> EvalResult:
    """Run ``episodes`` native episodes of ``task``; episode ``i`` resets with ``seed + i``.

    ``policy`` maps a raw observation (MountainCar's [x, v]) to an action (it applies any
    observation normalisation itself). Success is the task's rule (``Task.success``: terminated
    at the goal within the time limit). ``positions`` records the task's hovering coordinate
    (MountainCar's x) when it has one."""
    env = task.make_env()
    position = None if task.hover is None else task.hover.position
    returns, lengths, successes, positions = [], [], [], []
    try:
        for i in range(episodes):
            obs, _ = env.reset(seed=seed + i)
            total, length, done, terminated = 0.0, 0, False, False
            xs: list[float] = []
            while not done:
                obs, reward, terminated, truncated, _ = env.step(policy(obs))
                total += float(reward)
                length += 1
                if position is not None:
                    xs.append(position(obs))
                done = terminated or truncated
            returns.append(total)
            lengths.append(length)
            successes.append(task.success(terminated, length))
            if position is not None:
                positions.append(np.asarray(xs))
    finally:
        env.close()
    return EvalResult(np.asarray(returns), np.asarray(lengths), np.asarray(successes, dtype=float), tuple(positions),
                      task.hover_from)
