"""Detached evaluation: the trained policy alone, no VLM, no shaping, no rendering."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from vlmrl_cli.training.callbacks import SUCCESS_LENGTH

Policy = Callable[[np.ndarray], int]


@dataclass(frozen=True)
class EvalResult:
    """Per-episode figures of a detached evaluation, each shape (episodes,)."""

    returns: np.ndarray
    lengths: np.ndarray
    successes: np.ndarray

    @property
    def success_rate(self) -> float:
        return float(self.successes.mean())

    @property
    def mean_length(self) -> float:
        return float(self.lengths.mean())

    @property
    def mean_return(self) -> float:
        return float(self.returns.mean())


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
    returns, lengths, successes = [], [], []
    try:
        for i in range(episodes):
            obs, _ = env.reset(seed=seed + i)
            total, length, done, terminated = 0.0, 0, False, False
            while not done:
                obs, reward, terminated, truncated, _ = env.step(policy(obs))
                total += float(reward)
                length += 1
                done = terminated or truncated
            returns.append(total)
            lengths.append(length)
            successes.append(bool(terminated) and length <= SUCCESS_LENGTH)
    finally:
        env.close()
    return EvalResult(np.asarray(returns), np.asarray(lengths), np.asarray(successes, dtype=float))
