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
    """Per-episode figures of a detached evaluation, each shape (episodes,); ``positions``: the
    task's position after each step, one ``(length_i,)`` array per episode (empty if not recorded)."""

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
    """Run ``episodes`` native episodes of ``task`` (episode ``i`` reset with ``seed + i``) under
    ``policy``, which maps a raw observation to an action (normalising it itself)."""
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
