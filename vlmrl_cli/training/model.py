"""The PPO learner of one run, built in one place for the worker and the determinism probe."""

from __future__ import annotations

import functools
import operator
from collections.abc import Callable
from typing import Any

from vlmrl_cli.training.presets import PPOConfig


def learning_rate(ppo: PPOConfig) -> float | Callable[[float], float]:
    """SB3's ``learning_rate`` argument: a constant, or a schedule of the remaining progress
    (1 at the start, 0 at the budget) for ``lr_schedule = "linear"``.

    Example:
        >>> from vlmrl_cli.training.presets import PPOConfig
        >>> lr = learning_rate(PPOConfig(learning_rate=1e-3, lr_schedule="linear"))
        >>> lr(1.0), lr(0.25)
        (0.001, 0.00025)
    """
    if ppo.lr_schedule == "linear":  # the rate times the remaining progress
        return functools.partial(operator.mul, ppo.learning_rate)
    return ppo.learning_rate


#: Adam's multi-tensor update: part of the numeric path, not a knob (docs/development.md).
OPTIMIZER_KWARGS = {"foreach": True}


def make_model(ppo: PPOConfig, env: Any, seed: int) -> Any:
    """A ``PPO("MlpPolicy", env)`` with every knob of ``ppo``, on the CPU, seeded ``seed``, and a
    logger that writes nowhere (without one ``learn()`` makes an empty temp folder every call)."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import Logger

    model = PPO(
        "MlpPolicy",
        env,
        n_steps=ppo.n_steps,
        batch_size=ppo.batch_size,
        n_epochs=ppo.n_epochs,
        learning_rate=learning_rate(ppo),
        gamma=ppo.gamma,
        gae_lambda=ppo.gae_lambda,
        clip_range=ppo.clip_range,
        ent_coef=ppo.ent_coef,
        vf_coef=ppo.vf_coef,
        max_grad_norm=ppo.max_grad_norm,
        use_sde=ppo.use_sde,
        policy_kwargs={**ppo.policy_kwargs, "optimizer_kwargs": dict(OPTIMIZER_KWARGS)},
        seed=seed,
        device="cpu",
        verbose=0,
    )
    model.set_logger(Logger(folder=None, output_formats=[]))
    return model
