from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecNormalize

from tests.shaping import sim_client
from vlmrl_cli.shaping.arms import ARMS
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.shaping.semantic import SemanticOracle
from vlmrl_cli.shaping.wrapper import EpisodeStatistics, LabelRoundVecEnv, SemanticPotential
from vlmrl_cli.tasks.base import Task
from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.training.envs import make_train_env
from vlmrl_cli.training.presets import preset_of

SMOKE = preset_of(get_task("mountain-car"), "smoke")  # 2 envs, VecNormalize on


def wrappers(venv: VecEnv) -> list[SemanticPotential]:
    """The semantic wrapper of each env of a hybrid run's stack (below its EpisodeStatistics)."""
    base = venv.venv if isinstance(venv, VecNormalize) else venv
    assert isinstance(base, LabelRoundVecEnv)
    assert all(isinstance(env, EpisodeStatistics) for env in base.envs), "every stack ends in EpisodeStatistics"
    envs = [e.env for e in base.envs if isinstance(e, EpisodeStatistics) and isinstance(e.env, SemanticPotential)]
    assert len(envs) == base.num_envs, "every env of a hybrid stack holds a SemanticPotential"
    return envs


@pytest.mark.parametrize("name", list(ARMS))
def test_every_arm_builds_steps_and_reports_native_episode_stats(name: str) -> None:
    arm = ARMS[name]
    client = sim_client() if arm.uses_vlm else None
    venv, oracle = make_train_env(arm, SMOKE, ShapingConfig(), client, seed=3, task=MOUNTAIN_CAR)
    assert isinstance(venv, VecNormalize) and venv.num_envs == SMOKE.n_envs
    assert (oracle is not None) == arm.uses_vlm
    venv.reset()
    rng = np.random.default_rng(0)
    finished = []
    for _ in range(201):
        _, _, dones, infos = venv.step(rng.integers(0, 3, size=venv.num_envs))
        assert all("native_reward" in info for info in infos)
        finished += [info for info, done in zip(infos, dones, strict=True) if done]
    assert finished, "random actions must hit the 200-step time limit"
    for info in finished:
        assert info["episode"]["r"] == -info["episode"]["l"]  # Monitor: the NATIVE return
        assert "shaped_return" in info and "is_success" in info
    if oracle is not None:
        stats = oracle.stats()
        assert stats["vlm/queries"] > 0 and stats["vlm/prototypes"] > 0
    venv.close()


def test_env_i_is_seeded_seed_plus_i() -> None:
    preset = dataclasses.replace(SMOKE, n_envs=3, normalize_obs=False, normalize_reward=False)
    venv, _ = make_train_env(ARMS["kinematic"], preset, ShapingConfig(), None, seed=40, task=MOUNTAIN_CAR)
    assert isinstance(venv, DummyVecEnv)
    obs = np.asarray(venv.reset())
    for i in range(3):
        expected, _ = gym.make("MountainCar-v0").reset(seed=40 + i)
        np.testing.assert_array_equal(obs[i], expected)


def test_camera_and_oracle_are_shared_and_gamma_defaults_to_the_learner() -> None:
    venv, oracle = make_train_env(ARMS["hybrid"], SMOKE, ShapingConfig(), sim_client(), seed=0, task=MOUNTAIN_CAR)
    envs = wrappers(venv)
    assert envs[0].camera is envs[1].camera is not None
    assert all(env.episode.oracle is oracle for env in envs)
    assert isinstance(oracle, SemanticOracle)
    assert all(env._gamma == SMOKE.gamma for env in envs)
    venv.close()
    venv, _ = make_train_env(ARMS["hybrid"], SMOKE, ShapingConfig(gamma=0.9), sim_client(), seed=0, task=MOUNTAIN_CAR)
    assert all(env._gamma == 0.9 for env in wrappers(venv))


def test_same_seed_same_shaped_rewards() -> None:
    preset = dataclasses.replace(SMOKE, normalize_obs=False, normalize_reward=False)
    actions = np.random.default_rng(2).integers(0, 3, size=(300, preset.n_envs))
    runs = []
    for _ in range(2):
        venv, _ = make_train_env(ARMS["hybrid"], preset, ShapingConfig(), sim_client(), seed=9, task=MOUNTAIN_CAR)
        venv.reset()
        runs.append(np.array([venv.step(a)[1] for a in actions]))
    np.testing.assert_array_equal(runs[0], runs[1])


def test_a_vlm_arm_needs_a_client() -> None:
    with pytest.raises(ValueError, match="VLMClient"):
        make_train_env(ARMS["hybrid"], SMOKE, ShapingConfig(), None, seed=0, task=MOUNTAIN_CAR)


def test_ppo_trains_on_the_hybrid_env() -> None:
    from stable_baselines3 import PPO

    venv, oracle = make_train_env(ARMS["hybrid"], SMOKE, ShapingConfig(), sim_client(), seed=0, task=MOUNTAIN_CAR)
    model = PPO("MlpPolicy", venv, n_steps=SMOKE.n_steps, batch_size=SMOKE.batch_size, n_epochs=1, seed=0,
                device="cpu")
    model.learn(total_timesteps=256)
    assert oracle is not None and oracle.stats()["vlm/queries"] > 0
    venv.close()


def _as_uint8(env: gym.Env) -> gym.Env:
    """MountainCar's observation quantised to a uint8 Box (as MiniGrid's image is)."""
    low, high = env.observation_space.low, env.observation_space.high  # type: ignore[attr-defined]
    space = gym.spaces.Box(0, 255, (2,), np.uint8)
    return gym.wrappers.TransformObservation(
        env, lambda o: np.round(255 * (o - low) / (high - low)).astype(np.uint8), space)


UINT8_TASK = dataclasses.replace(MOUNTAIN_CAR, name="uint8-car", wrap=_as_uint8)


def test_a_uint8_observation_reaches_ppo_as_float_under_vecnormalize() -> None:
    """SB3's rollout buffer stores observations in the space's dtype: a uint8 Box under VecNormalize
    would truncate every normalised observation to an integer (DoorKey's bug, issue 41)."""
    from stable_baselines3 import PPO

    assert UINT8_TASK.make_env().observation_space.dtype == np.uint8
    venv, _ = make_train_env(ARMS["baseline"], SMOKE, ShapingConfig(), None, seed=0, task=UINT8_TASK)
    assert isinstance(venv, VecNormalize) and venv.observation_space.dtype == np.float32
    model = PPO("MlpPolicy", venv, n_steps=SMOKE.n_steps, batch_size=SMOKE.batch_size, n_epochs=1, seed=0,
                device="cpu")
    model.learn(total_timesteps=SMOKE.n_steps * SMOKE.n_envs)
    stored = model.rollout_buffer.observations
    assert stored.dtype == np.float32
    assert np.any(stored != np.round(stored)), "normalised observations keep their fractions"
    assert float(np.abs(stored).max()) < 11.0, "and are VecNormalize's (clipped at 10), not raw pixels"
    venv.close()


def test_a_float_observation_is_left_as_it_is() -> None:
    venv, _ = make_train_env(ARMS["baseline"], SMOKE, ShapingConfig(), None, seed=0, task=MOUNTAIN_CAR)
    base = venv.venv if isinstance(venv, VecNormalize) else venv
    assert isinstance(base, DummyVecEnv)
    env = base.envs[0]
    while isinstance(env, gym.Wrapper):
        assert not isinstance(env, gym.wrappers.DtypeObservation)
        env = env.env
    assert venv.observation_space == MOUNTAIN_CAR.make_env().observation_space
    venv.close()


def _survived(terminated: bool, length: int) -> bool:
    """A rule of another kind of task: lasting the whole time limit is the success."""
    return not terminated and length >= MOUNTAIN_CAR.max_steps


SURVIVE_TASK = dataclasses.replace(MOUNTAIN_CAR, name="survive-car", success_rule=_survived)


def _push(obs: np.ndarray) -> int:
    """Push in the direction of motion: MountainCar's goal in about 120 steps."""
    return 2 if obs[1] >= 0 else 0


def _idle(obs: np.ndarray) -> int:
    return 1  # no push: the time limit ends it


@pytest.mark.parametrize(("task", "expected"), [(MOUNTAIN_CAR, [True, False]), (SURVIVE_TASK, [False, True])],
                         ids=["built-in-rule", "own-rule"])
@pytest.mark.parametrize("arm", ["baseline", "hybrid"])
def test_the_tasks_success_rule_decides_the_wrapper_the_tracker_and_the_evaluation(
        task: Task, expected: list[bool], arm: str) -> None:
    """One rule: ``is_success`` of the training env, the tracked ``episode/success`` and the
    detached evaluation's successes are all the task's, for the goal (push) and the time limit (idle)."""
    from vlmrl_cli.training.callbacks import EpisodeTracker
    from vlmrl_cli.training.evaluation import evaluate_detached

    preset = dataclasses.replace(SMOKE, n_envs=1, normalize_obs=False, normalize_reward=False)
    spec = ARMS[arm]
    venv, _ = make_train_env(spec, preset, ShapingConfig(), sim_client() if spec.uses_vlm else None, seed=0,
                             task=task)
    tracker = EpisodeTracker("rule-s0", total=1_000, success=task.success)
    ends = []
    obs = np.asarray(venv.reset())
    for policy in (_push, _idle):
        while True:
            step_obs, _, dones, infos = venv.step(np.array([policy(obs[0])]))
            obs = np.asarray(step_obs)
            if dones[0]:
                ends.append(infos[0])
                tracker.num_timesteps += int(infos[0]["episode"]["l"])
                tracker.locals = {"infos": infos}
                tracker._on_step()
                break
    venv.close()
    assert [info["episode"]["l"] < task.max_steps for info in ends] == [True, False]  # the goal, then the limit
    assert [info["is_success"] for info in ends] == expected
    assert [e["episode/success"] for e in tracker.episodes] == [float(ok) for ok in expected]
    detached = [evaluate_detached(policy, 1, 0, task).successes.tolist() for policy in (_push, _idle)]
    assert detached == [[float(ok)] for ok in expected]
