"""The paper's task, MountainCar-v0, and its continuous-action twin MountainCarContinuous-v0, which
share the track, car and camera. MountainCar-v0's runs predate the task plug-ins and keep their
config hashes (tests/training/test_pinned_hashes.py). See docs/tasks.md."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
from gymnasium.envs.classic_control.continuous_mountain_car import Continuous_MountainCarEnv
from gymnasium.envs.classic_control.mountain_car import MountainCarEnv

from vlmrl_cli.frames.render import Frame
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.shaping.features import FEATURE_DIM
from vlmrl_cli.shaping.scales import task_scales
from vlmrl_cli.shaping.scene import Scene
from vlmrl_cli.tasks.base import SB3_DEFAULT_100K, SMOKE, RandomScore, Task
from vlmrl_cli.tasks.capabilities import Hover, PaperTask, TaskCamera
from vlmrl_cli.tasks.mountain_car import geometry
from vlmrl_cli.tasks.mountain_car.camera import Camera
from vlmrl_cli.tasks.mountain_car.probe import NUMBER_PROBE
from vlmrl_cli.tasks.mountain_car.profiles import SIM_PROFILES
from vlmrl_cli.tasks.mountain_car.prompts import ZONE_MILESTONES
from vlmrl_cli.tasks.mountain_car.reader import WheelReader, wheel_column
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer

# Raw potential of each MCQ label (Phi_raw): the paper fixes only the left peak's 0.3 (docs/method.md).
ZONE_POTENTIALS: tuple[tuple[str, float], ...] = (
    ("LEFT_PEAK", 0.3),
    ("LEFT_SLOPE", 0.1),
    ("BOTTOM", 0.0),
    ("RIGHT_SLOPE", 0.1),
    ("NEAR_GOAL", 0.6),
    ("GOAL", 1.0),
)

CONTINUOUS_ENV_ID = "MountainCarContinuous-v0"
CONTINUOUS_GOAL = 0.45  # MountainCarContinuous-v0's flag
CONTINUOUS_EDGES: tuple[float, ...] = (*geometry.ZONE_EDGES[:-1], CONTINUOUS_GOAL)


def kinematic_dense(obs: np.ndarray, scale: float, offset: float) -> float:
    """Paper Eq. 1 on the position ``obs[0]``: ``R_kin = max(0, scale (x + offset))`` per step."""
    return max(0.0, scale * (float(obs[0]) + offset))  # every env step: kept to one expression


MOUNTAIN_CAR_SCENE = Scene("mountain-car", (2,), kinematic_dense, MountainCarEnv)


ACTIONS = {0: "push left", 1: "no push", 2: "push right"}


def describe_step(obs: tuple[float, ...], action: Any) -> tuple[dict[str, Any], str]:
    """A played step of MountainCar-v0 as named fields and ``vlmrl evaluate``'s caption.

    Example:
        >>> describe_step((-0.5, 0.01), 2)
        ({'x': -0.5, 'v': 0.01}, 'x -0.500  v +0.0100  action push right')
    """
    x, v = obs[0], obs[1]
    shown = ACTIONS.get(action, str(action)) if action is not None else "-"
    return {"x": x, "v": v}, f"x {x:+.3f}  v {v:+.4f}  action {shown}"


def _position(obs: np.ndarray) -> float:
    return float(obs[0])


def _zone_of_sim(sim: Any, edges: tuple[float, ...] = geometry.ZONE_EDGES) -> str:
    return str(geometry.zone_of(float(sim.state[0]), edges))


class ContinuousZoneReader:
    """MountainCarContinuous-v0's reader: the zone of the wheels' column (pixels only), GOAL from 0.45."""

    name = "mountain-car-continuous"
    milestones = ZONE_MILESTONES

    def read(self, pixels: np.ndarray) -> str | None:
        column = wheel_column(pixels)
        if column is None:
            return None
        x = float(np.clip(geometry.x_from_column(column), geometry.MIN_POSITION, geometry.MAX_POSITION))
        return str(geometry.zone_of(x, CONTINUOUS_EDGES))


def continuous_probe_states(n: int) -> list[np.ndarray]:
    """``n`` positions evenly spaced over the track (velocity 0).

    Example:
        >>> [round(float(s[0]), 2) for s in continuous_probe_states(3)]
        [-1.2, -0.3, 0.6]
    """
    return [np.array([x, 0.0]) for x in np.linspace(geometry.MIN_POSITION, geometry.MAX_POSITION, n)]


def _grid_frames(shaping: ShapingConfig) -> list[Frame]:
    """Every frame MountainCar-v0's camera shows under ``shaping`` (one per grid position)."""
    with FrameRenderer() as renderer:
        return [renderer.render(x) for x in Camera(shaping.render_quantum).grid_positions()]


def _camera(shaping: ShapingConfig) -> Camera:
    return Camera(shaping.render_quantum)


def _continuous_camera(shaping: ShapingConfig) -> Camera:
    return Camera(shaping.render_quantum, env_id=CONTINUOUS_ENV_ID)


# rl-baselines3-zoo, hyperparams/ppo.yml, MountainCar-v0 (n_timesteps there: 1e6).
ZOO: dict[str, Any] = {
    "n_envs": 16, "n_steps": 16, "batch_size": 64, "gae_lambda": 0.98, "gamma": 0.99, "n_epochs": 4,
    "ent_coef": 0.0, "learning_rate": 3e-4, "normalize_obs": True, "normalize_reward": True, "timesteps": 1_000_000,
}

PRESETS: dict[str, dict[str, Any]] = {
    "zoo": ZOO,
    "sb3-default": {**SB3_DEFAULT_100K, "timesteps": 300_000},
    "smoke": {**SMOKE, "eval_episodes": 5},
    # the paper names no PPO knobs: zoo's, with a budget just above its largest threshold step (272,448)
    "paper": {**ZOO, "timesteps": 300_000},
    # the closest regime of the committed calibrations (results/calibration/calibration.md)
    "paper-calibrated": {**ZOO, "timesteps": 300_000, "normalize_reward": False},
    # a baseline that fails on some seeds (issue 18; 8/20 seeds, results/calibration/refine-lr/)
    "paper-unreliable": {**ZOO, "timesteps": 300_000, "normalize_reward": False, "learning_rate": 1.5e-4},
}

_NO_VECNORMALIZE = {"ppo.normalize_obs": False, "ppo.normalize_reward": False}
#: `vlmrl calibrate`'s default grid, relative to the base preset (`paper`: the zoo's PPO, 16 envs x
#: 16 steps, VecNormalize, 300,000 steps). Cost on 2 cores, 10 seeds each: about 85 minutes.
CALIBRATION: tuple[dict[str, Any], ...] = (
    {},  # the zoo's tuned PPO: solves every seed quickly
    {"ppo.learning_rate": 1e-4},  # a third of the step size
    {"ppo.normalize_reward": False},  # observations normalised, raw rewards
    _NO_VECNORMALIZE,  # raw observations and rewards
    {**_NO_VECNORMALIZE, "ppo.ent_coef": 0.01},  # ... with an entropy bonus to explore
    {"ppo.n_envs": 4, "ppo.n_steps": 64},  # fewer envs, the same 256-step rollouts
    {"ppo.n_envs": 1, "ppo.n_steps": 256},  # one env, the same 256-step rollouts
    # SB3's PPO defaults on one env: long rollouts, no normalisation (rarely solves in budget)
    {**_NO_VECNORMALIZE, "ppo.n_envs": 1, "ppo.n_steps": 2048, "ppo.n_epochs": 10, "ppo.gae_lambda": 0.95},
)

MOUNTAIN_CAR = Task(
    name="mountain-car",
    env_id="MountainCar-v0",
    summary="MountainCar-v0: the paper's task (3 actions, -1 per step, 200 steps)",
    scene=MOUNTAIN_CAR_SCENE,
    milestones=ZONE_MILESTONES,
    label_potentials=ZONE_POTENTIALS,
    truth=_zone_of_sim,
    camera=TaskCamera(_camera, FEATURE_DIM, frames=_grid_frames),
    reader=WheelReader(),  # the wheels' column: the zone, and the float and box answers
    thresholds=(-190.0, -160.0, -130.0),
    max_steps=200,
    presets=PRESETS,
    default_preset="paper",
    zoo_reference="rl-baselines3-zoo benchmark.md, PPO MountainCar-v0: -110.423 +/- 19.473 (1M steps)",
    random_score=RandomScore(-200.0),  # measured by RANDOM_SCORE_COMMAND on 2026-12-07
    hover=Hover(_position, start=0.3),
    numbers=NUMBER_PROBE,  # Table 1's float and box probe (probe.py)
    calibration=CALIBRATION,
    # the regime of `vlmrl study`: a baseline that fails on some seeds (see PRESETS above)
    study_preset="paper-unreliable",
    paper=PaperTask(),  # paper/reported.json is its Table 2; its runs predate tasks: their hashes name no task
    caption=describe_step,
    hacking_note=("hovering short of the flag",
                  "R_kin = max(0, 2(x + 0.4)) pays up to +1.8 per step just left of the flag, more than the -1 "
                  "step cost, so parking near x = 0.45 can pay more than finishing."),
    sim_profiles=SIM_PROFILES,  # llava-table1, the paper's Table 1 failures (profiles.py)
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

# MountainCar-v0's zoo knobs at 100,000 steps, for the continuous car
_MC_KNOBS: dict[str, Any] = {**ZOO, "timesteps": 100_000}

_SPAN = max(p for _, p in ZONE_POTENTIALS) - min(p for _, p in ZONE_POTENTIALS)

MOUNTAIN_CAR_CONTINUOUS = Task(
    name="mountain-car-continuous",
    env_id=CONTINUOUS_ENV_ID,
    summary="MountainCarContinuous-v0: force in [-1, 1], +100 at the flag minus 0.1 a^2 per step, 999 steps",
    scene=Scene("mountain-car-continuous", (2,), kinematic_dense, Continuous_MountainCarEnv),
    milestones=ZONE_MILESTONES,
    label_potentials=ZONE_POTENTIALS,
    truth=functools.partial(_zone_of_sim, edges=CONTINUOUS_EDGES),
    camera=TaskCamera(_continuous_camera, FEATURE_DIM),
    reader=ContinuousZoneReader(),
    thresholds=(0.0, 50.0, 90.0),  # 90: gymnasium's "solved"; below 0 the car never reached the flag
    max_steps=999,
    presets={
        "zoo": _CONTINUOUS_ZOO,
        # zoo's tuned knobs, a budget ten times zoo's: room to see a slow or stuck baseline
        "zoo-200k": {**_CONTINUOUS_ZOO, "timesteps": 200_000},
        # the candidates of `vlmrl calibrate --task mountain-car-continuous`, cheap on CPUs
        "mc-zoo-100k": _MC_KNOBS,
        "mc-zoo-100k-raw-reward": {**_MC_KNOBS, "normalize_reward": False},
        "sb3-default-100k": SB3_DEFAULT_100K,
        "smoke": SMOKE,
    },
    zoo_reference="rl-baselines3-zoo benchmark.md, PPO MountainCarContinuous-v0: 88.343 +/- 2.572 (20k steps)",
    random_score=RandomScore(-33.20757),  # measured by RANDOM_SCORE_COMMAND on 2026-12-07
    hover=Hover(_position, start=0.3),
    probe_states=continuous_probe_states,
    # an episode that never reaches the flag lasts 999 steps: 100 of them would be a whole budget
    window=10,
    calibration=tuple({"preset": p} for p in ("mc-zoo-100k", "mc-zoo-100k-raw-reward", "sb3-default-100k")),
    # the median of its 65 committed runs (calibration and study exports; quartiles 0.92-1.67 ms)
    step_seconds=1.21e-3,
    # goal: zoo's 88.3 over a failure's 0 (standing still); Eq. 1 pays at most 1.0 per step at scale 1
    # (x = 0.6); the label map spans 0 to 1
    scales=task_scales(goal_return=88.3, potential_span=_SPAN, dense_peak=1.0, horizon=999),
    # the closest calibrated regime (results/tasks/mountain-car-continuous/calibration/): 0/5 seeds
    study_preset="sb3-default-100k",
)
