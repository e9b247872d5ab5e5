"""Train PPO on MiniGrid-DoorKey-5x5-v0 with rl-baselines3-zoo's knobs, outside vlmrl, to check
whether the zoo's published score (benchmark.md: 0.964 +/- 0.006 at 100k steps) reproduces with
the installed minigrid and stable-baselines3, with MiniGrid's ``uint8`` observation as it comes and
cast to float32.

The ``uint8`` runs show issue 41's bug outside vlmrl: SB3's rollout buffer keeps the observation
space's dtype, so VecNormalize's normalised observations are truncated to integers and PPO learns
from garbage; cast to float32, zoo's recipe learns (vlmrl's harness casts every non-float Box
observation, ``training.envs.as_float``; its calibration on 2026-12-06 gave 0.964 on 5/5 seeds).

The zoo's recipe (hyperparams/ppo.yml, MiniGrid defaults): FlatObsWrapper, VecNormalize (obs and
reward), 8 envs, n_steps 128, batch 64, gae 0.95, gamma 0.99, 10 epochs, ent_coef 0, lr 2.5e-4,
clip 0.2, MlpPolicy, 100,000 steps. Prints, per seed, the mean return of the last 100 training
episodes and of 20 deterministic evaluation episodes (the zoo reports the latter), per dtype.

    OMP_NUM_THREADS=1 python scripts/zoo_doorkey_check.py 0 1 2
"""

from __future__ import annotations

import sys

import gymnasium as gym
import minigrid  # registers the MiniGrid envs
import numpy as np
import torch
from minigrid.wrappers import FlatObsWrapper
from stable_baselines3 import PPO
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.vec_env import VecNormalize

ENV_ID = "MiniGrid-DoorKey-5x5-v0"


def _float_obs(env: gym.Env) -> gym.Env:
    return gym.wrappers.DtypeObservation(FlatObsWrapper(env), np.float32)


def check(seed: int, as_float: bool) -> tuple[float, float]:
    torch.set_num_threads(1)
    wrapper = _float_obs if as_float else FlatObsWrapper
    venv = VecNormalize(make_vec_env(ENV_ID, n_envs=8, seed=seed, wrapper_class=wrapper), gamma=0.99)
    model = PPO("MlpPolicy", venv, n_steps=128, batch_size=64, gae_lambda=0.95, gamma=0.99, n_epochs=10,
                ent_coef=0.0, learning_rate=2.5e-4, clip_range=0.2, seed=seed, verbose=0)
    model.learn(100_000)
    train = float(np.mean([e["r"] for e in model.ep_info_buffer])) if model.ep_info_buffer else float("nan")
    venv.training, venv.norm_reward = False, False
    returns, _ = evaluate_policy(model, venv, n_eval_episodes=20, deterministic=True, return_episode_rewards=True)
    return train, float(np.mean(returns))


if __name__ == "__main__":
    print(f"{ENV_ID}, zoo's PPO knobs, 100,000 steps, minigrid {minigrid.__version__}, gymnasium {gym.__version__}")
    for arg in sys.argv[1:] or ["0"]:
        for as_float in (False, True):
            train, evaluated = check(int(arg), as_float)
            print(f"seed {arg}, observation {'float32' if as_float else 'uint8'}: last-100 training return "
                  f"{train:.3f}, deterministic evaluation (20 episodes) {evaluated:.3f}", flush=True)
