"""The paper's task, MountainCar-v0, and its continuous-action twin MountainCarContinuous-v0.

Both share the track, the car and the camera (the picture depends on the position only, so at
most 601 distinct frames at the default 0.003 grid). MountainCar-v0's pieces predate the task
plug-ins and stay where they were (``frames/geometry.py``, ``shaping/camera.py``, the simulated
VLM's built-in wheel reader); its runs keep their config hashes.

MountainCarContinuous-v0: force in [-1, 1], reward +100 at the flag (x >= 0.45) minus
``0.1 a^2`` per step, 999 steps. Plain PPO often settles on standing still (the action cost
punishes exploration): the paper's "exploration deadlock" in its clearest form.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.envs.classic_control.continuous_mountain_car import Continuous_MountainCarEnv

from vlmrl_cli.frames import geometry
from vlmrl_cli.shaping.camera import Camera
from vlmrl_cli.shaping.config import DEFAULT_LABEL_POTENTIALS, ShapingConfig
from vlmrl_cli.shaping.features import FEATURE_DIM
from vlmrl_cli.shaping.scene import MOUNTAIN_CAR as MOUNTAIN_CAR_SCENE
from vlmrl_cli.shaping.scene import Scene, mountain_car_dense
from vlmrl_cli.tasks.base import SB3_DEFAULT_100K, SMOKE, Task
from vlmrl_cli.vlm.prompts import ZONE_MILESTONES
from vlmrl_cli.vlm.sim import wheel_column

CONTINUOUS_ENV_ID = "MountainCarContinuous-v0"
CONTINUOUS_GOAL = 0.45  # MountainCarContinuous-v0's flag
CONTINUOUS_EDGES: tuple[float, ...] = (*geometry.ZONE_EDGES[:-1], CONTINUOUS_GOAL)


def _position(obs: np.ndarray) -> float:
    return float(obs[0])


def _zone_of_sim(sim: Any) -> str:
    return geometry.zone_of(float(sim.state[0]))


def _continuous_zone_of_sim(sim: Any) -> str:
    return geometry.zone_of(float(sim.state[0]), CONTINUOUS_EDGES)


class ContinuousZoneReader:
    """The simulated VLM's reader for MountainCarContinuous-v0: the car's wheels in the pixels
    (``wheel_column``, as MountainCar's built-in reader), their column mapped back to a position,
    the zone of that position with GOAL from the flag at 0.45. Pixels only, never the state.

    Example:
        >>> from vlmrl_cli.frames.render import FrameRenderer
        >>> with FrameRenderer(CONTINUOUS_ENV_ID) as renderer:
        ...     ContinuousZoneReader().read(renderer.render(0.47).pixels)
        'GOAL'
    """

    name = "mountain-car-continuous"
    milestones = ZONE_MILESTONES

    def read(self, pixels: np.ndarray) -> str | None:
        column = wheel_column(pixels)
        if column is None:
            return None
        x = float(np.clip(geometry.x_from_column(column), geometry.MIN_POSITION, geometry.MAX_POSITION))
        return str(geometry.zone_of(x, CONTINUOUS_EDGES))


def continuous_probe_states(n: int) -> list[np.ndarray]:
    """``n`` positions evenly spaced over the track (velocity 0), for the taxonomy.

    Example:
        >>> [round(float(s[0]), 2) for s in continuous_probe_states(3)]
        [-1.2, -0.3, 0.6]
    """
    return [np.array([x, 0.0]) for x in np.linspace(geometry.MIN_POSITION, geometry.MAX_POSITION, n)]


def _camera(shaping: ShapingConfig) -> Camera:
    return Camera(shaping.render_quantum)


def _continuous_camera(shaping: ShapingConfig) -> Camera:
    return Camera(shaping.render_quantum, env_id=CONTINUOUS_ENV_ID)


MOUNTAIN_CAR = Task(
    name="mountain-car",
    env_id="MountainCar-v0",
    summary="MountainCar-v0: the paper's task (3 actions, -1 per step, 200 steps)",
    scene=MOUNTAIN_CAR_SCENE,
    milestones=ZONE_MILESTONES,
    label_potentials=DEFAULT_LABEL_POTENTIALS,
    truth=_zone_of_sim,
    make_camera=_camera,
    reader=None,  # the simulated VLM's built-in wheel reader (with the float and box answers)
    feature_dim=FEATURE_DIM,
    thresholds=(-190.0, -160.0, -130.0),
    max_steps=200,
    presets=None,  # training/presets.py: zoo, sb3-default, smoke, paper, paper-calibrated, paper-unreliable
    default_preset="paper",
    zoo_reference="rl-baselines3-zoo benchmark.md, PPO MountainCar-v0: -110.423 +/- 19.473 (1M steps)",
    position=_position,
    hover_from=0.3,
    probes_floats=True,
)

# rl-baselines3-zoo, hyperparams/ppo.yml, MountainCarContinuous-v0 ("Tuned"; n_timesteps 2e4,
# normalize: true). Its batch_size 256 exceeds the 8-step rollout, so SB3 takes the whole
# rollout as one minibatch: batch_size 8 here is the same update. Its policy_kwargs:
# log_std_init=-3.29, ortho_init=False.
_CONTINUOUS_ZOO: dict[str, Any] = {
    "n_envs": 1, "n_steps": 8, "batch_size": 8, "gamma": 0.9999, "learning_rate": 7.77e-05, "ent_coef": 0.00429,
    "clip_range": 0.1, "n_epochs": 10, "gae_lambda": 0.9, "max_grad_norm": 5.0, "vf_coef": 0.19, "use_sde": True,
    "log_std_init": -3.29, "ortho_init": False, "normalize_obs": True, "normalize_reward": True,
    "timesteps": 20_000,
}

# MountainCar-v0's zoo knobs (training/presets.ZOO) at 100,000 steps, for the continuous car
_MC_KNOBS: dict[str, Any] = {
    "n_envs": 16, "n_steps": 16, "batch_size": 64, "gae_lambda": 0.98, "gamma": 0.99, "n_epochs": 4,
    "ent_coef": 0.0, "learning_rate": 3e-4, "normalize_obs": True, "normalize_reward": True, "timesteps": 100_000,
}

MOUNTAIN_CAR_CONTINUOUS = Task(
    name="mountain-car-continuous",
    env_id=CONTINUOUS_ENV_ID,
    summary="MountainCarContinuous-v0: force in [-1, 1], +100 at the flag minus 0.1 a^2 per step, 999 steps",
    scene=Scene("mountain-car-continuous", (2,), mountain_car_dense, Continuous_MountainCarEnv),
    milestones=ZONE_MILESTONES,
    label_potentials=DEFAULT_LABEL_POTENTIALS,
    truth=_continuous_zone_of_sim,
    make_camera=_continuous_camera,
    reader=ContinuousZoneReader(),
    feature_dim=FEATURE_DIM,
    thresholds=(0.0, 50.0, 90.0),  # 90: gymnasium's "solved"; below 0 the car never reached the flag
    max_steps=999,
    presets={
        "zoo": _CONTINUOUS_ZOO,
        # zoo's tuned knobs, a budget ten times zoo's: room to see a slow or stuck baseline
        "zoo-200k": {**_CONTINUOUS_ZOO, "timesteps": 200_000},
        # The candidates of `vlmrl calibrate --task mountain-car-continuous` (Task.calibration),
        # 100,000 steps each, all cheap to train on CPUs (zoo's tuned 8-step rollouts with 10
        # epochs cost about ten times as much per step): MountainCar-v0's zoo knobs (16 envs x
        # 16 steps, VecNormalize), the same without reward normalisation, and SB3's PPO defaults
        # on one env (no normalisation). Untuned PPO is known to settle on standing still here.
        "mc-zoo-100k": _MC_KNOBS,
        "mc-zoo-100k-raw-reward": {**_MC_KNOBS, "normalize_reward": False},
        "sb3-default-100k": SB3_DEFAULT_100K,
        "smoke": SMOKE,
    },
    default_preset="zoo",
    zoo_reference="rl-baselines3-zoo benchmark.md, PPO MountainCarContinuous-v0: 88.343 +/- 2.572 (20k steps)",
    position=_position,
    hover_from=0.3,
    probe_states=continuous_probe_states,
    # an episode that never reaches the flag lasts 999 steps: 100 of them would be a whole budget
    window=10,
    calibration=tuple({"preset": p} for p in ("mc-zoo-100k", "mc-zoo-100k-raw-reward", "sb3-default-100k")),
    # The closest regime of `vlmrl calibrate --task mountain-car-continuous --seeds 5` (results/tasks/
    # mountain-car-continuous/calibration/, 2026-12-02): distance 0.877. Its baseline never reached
    # the flag (0/5 seeds, detached success 0%): the "exploration deadlock" of the paper.
    study_preset="sb3-default-100k",
)
