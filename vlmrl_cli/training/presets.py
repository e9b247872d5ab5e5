"""PPO presets. `paper` is the one used to reproduce the paper (see its docstring)."""

from __future__ import annotations

from dataclasses import dataclass, replace

from vlmrl_cli.core.errors import BadInput


@dataclass(frozen=True)
class PPOPreset:
    """PPO hyperparameters and the default budget (SB3 names)."""

    name: str
    n_envs: int
    n_steps: int
    batch_size: int
    gae_lambda: float
    gamma: float
    n_epochs: int
    ent_coef: float
    learning_rate: float
    normalize: bool  # VecNormalize on observations and rewards
    timesteps: int
    eval_episodes: int = 100


# rl-baselines3-zoo, hyperparams/ppo.yml, MountainCar-v0 (n_timesteps there: 1e6).
ZOO = PPOPreset("zoo", n_envs=16, n_steps=16, batch_size=64, gae_lambda=0.98, gamma=0.99,
                n_epochs=4, ent_coef=0.0, learning_rate=3e-4, normalize=True, timesteps=1_000_000)

PRESETS: dict[str, PPOPreset] = {
    p.name: p
    for p in (
        ZOO,
        PPOPreset("sb3-default", n_envs=1, n_steps=2048, batch_size=64, gae_lambda=0.95, gamma=0.99,
                  n_epochs=10, ent_coef=0.0, learning_rate=3e-4, normalize=False, timesteps=300_000),
        PPOPreset("smoke", n_envs=2, n_steps=64, batch_size=64, gae_lambda=0.95, gamma=0.99,
                  n_epochs=1, ent_coef=0.0, learning_rate=3e-4, normalize=True, timesteps=1_024,
                  eval_episodes=5),
        # The paper names no PPO hyperparameters. We reproduce it with the public tuned
        # configuration for this environment (zoo) and a 300,000-step budget, just above the
        # largest threshold step the paper reports (272,448).
        replace(ZOO, name="paper", timesteps=300_000),
    )
}


def get_preset(name: str) -> PPOPreset:
    if name not in PRESETS:
        raise BadInput(f"unknown preset '{name}'; choose from {', '.join(PRESETS)}.")
    return PRESETS[name]
