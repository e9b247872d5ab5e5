"""Detached evaluation: the trained policy alone, no VLM, no shaping, no rendering."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import gymnasium as gym
import numpy as np

from vlmrl_cli.shaping.hacking import HoverSummary, summarize_hovering
from vlmrl_cli.training.events import episode_success

Policy = Callable[[np.ndarray], int]


@dataclass(frozen=True)
class EvalResult:
    """Per-episode figures of a detached evaluation, each shape (episodes,).

    ``positions``: one array of shape ``(length_i,)`` per episode, the car's x after each step
    (for the hovering diagnostic; empty when not recorded).
    """

    returns: np.ndarray
    lengths: np.ndarray
    successes: np.ndarray
    positions: tuple[np.ndarray, ...] = field(default=())

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
        """Hover fraction and dwell right of x = 0.3 (see ``shaping.hacking``); NaN without positions."""
        return summarize_hovering(self.positions, self.successes > 0.5) if self.positions else HoverSummary(
            float("nan"), float("nan"), 0)


def evaluate_detached(policy: Policy, episodes: int, seed: int) -> EvalResult:
    """Run ``episodes`` native MountainCar-v0 episodes; episode ``i`` resets with ``seed + i``.

    ``policy`` maps a raw observation [x, v] to an action (it applies any observation
    normalisation itself). Success means the flag was reached before the 200-step limit.

    Example:
        >>> r = evaluate_detached(lambda obs: 2 if obs[1] >= 0 else 0, episodes=3, seed=0)
        >>> r.success_rate, bool(r.mean_length < 200)
        (1.0, True)
    """
    env = gym.make("MountainCar-v0")
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
                xs.append(float(obs[0]))
                done = terminated or truncated
            returns.append(total)
            lengths.append(length)
            successes.append(episode_success(terminated, length))
            positions.append(np.asarray(xs))
    finally:
        env.close()
    return EvalResult(np.asarray(returns), np.asarray(lengths), np.asarray(successes, dtype=float), tuple(positions))
