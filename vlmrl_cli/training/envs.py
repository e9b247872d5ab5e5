"""Build the training and evaluation envs; the wrapper stack is spelled out here, in order."""

from __future__ import annotations

from collections.abc import Callable

import gymnasium as gym
import numpy as np
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecNormalize

from vlmrl_cli.shaping.arms import ArmSpec
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.shaping.placebo import oracle_shaping
from vlmrl_cli.shaping.semantic import SemanticOracle
from vlmrl_cli.shaping.wrapper import LabelRoundVecEnv, wrap_arm
from vlmrl_cli.tasks.base import Task
from vlmrl_cli.training.presets import PPOConfig
from vlmrl_cli.vlm.client import VLMClient


def make_train_env(
    arm: ArmSpec,
    ppo: PPOConfig,
    shaping: ShapingConfig,
    client: VLMClient | None,
    seed: int,
    task: Task,
    max_queries: int | None = None,
) -> tuple[VecEnv, SemanticOracle | None]:
    """The training VecEnv of one run of ``task`` (env ``i`` seeded ``seed + i``; ``Monitor`` below the
    arm's wrappers, so episode stats are NATIVE) and its oracle (None for arms without a VLM)."""
    if arm.uses_vlm and client is None:
        raise ValueError(f"arm '{arm.name}' queries a VLM; pass a VLMClient (e.g. the simulated one).")
    shaping = task.shaping_for(shaping)
    gamma = shaping.gamma if shaping.gamma is not None else ppo.gamma
    camera = task.camera.make(shaping) if arm.uses_vlm else None
    oracle = (SemanticOracle(client, oracle_shaping(arm, shaping, seed), arm.potential, task.milestones,
                             task.camera.feature_dim, rbf=arm.rbf, numbers=task.numbers, max_queries=max_queries)
              if arm.uses_vlm and client else None)

    def make_one() -> gym.Env:
        env: gym.Env = as_float(task.make_env())
        env = Monitor(env)
        return wrap_arm(env, arm, shaping, gamma, task.scene, camera=camera, oracle=oracle, horizon=task.max_steps,
                        success=task.success)

    fns: list[Callable[[], gym.Env]] = [make_one] * ppo.n_envs
    venv: VecEnv = LabelRoundVecEnv(fns, oracle) if oracle is not None else DummyVecEnv(fns)
    venv.seed(seed)
    if ppo.normalize_obs or ppo.normalize_reward:
        venv = VecNormalize(venv, norm_obs=ppo.normalize_obs, norm_reward=ppo.normalize_reward, gamma=ppo.gamma)
    return venv, oracle


def as_float(env: gym.Env) -> gym.Env:
    """``env`` with a non-float ``Box`` observation cast to float32 (SB3's rollout buffer keeps the
    space's dtype, so ``VecNormalize`` would truncate a ``uint8`` one); any other env as it is.

    Example:
        >>> space = gym.spaces.Box(0, 255, (3,), np.uint8)
        >>> env = gym.wrappers.TransformObservation(gym.make("CartPole-v1"), lambda o: np.zeros(3, np.uint8), space)
        >>> as_float(env).observation_space.dtype, as_float(gym.make("CartPole-v1")).observation_space.dtype
        (dtype('float32'), dtype('float32'))
    """
    space = env.observation_space
    if isinstance(space, gym.spaces.Box) and not np.issubdtype(space.dtype, np.floating):
        return gym.wrappers.DtypeObservation(env, np.float32)
    return env
