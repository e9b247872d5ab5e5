"""gymnasium's and SB3's env checkers on every built-in task, bare and under every arm it supports,
the per-env stack taken from ``make_train_env`` itself (so that it is the stack training steps)."""

from __future__ import annotations

import contextlib
import dataclasses
import warnings
from collections.abc import Iterator

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gymnasium_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from vlmrl_cli.shaping.arms import ARMS, ArmSpec, PotentialSource
from vlmrl_cli.shaping.wrapper import EpisodeStatistics
from vlmrl_cli.tasks.base import Task
from vlmrl_cli.tasks.registry import get_task, task_names
from vlmrl_cli.training.envs import make_train_env
from vlmrl_cli.training.presets import preset_of
from vlmrl_cli.vlm.config import VLMConfig
from vlmrl_cli.vlm.registry import build_client

# The checkers' notices that are no finding: gymnasium says it checks a wrapped env (which is the
# point here), MiniGrid's human-mode render looks for a font this machine may not have, and MuJoCo's
# Pusher observes joint velocities, which have no bound.
EXPECTED_NOTICES = ("is different from the unwrapped version", "freesansbold",
                    "observation space minimum value is -infinity", "observation space maximum value is infinity")


def supports(task: Task, arm: ArmSpec) -> bool:
    """Whether a run of ``task`` may take ``arm`` (``vision-float`` asks for a number: ``probes_floats``)."""
    return arm.potential is not PotentialSource.FLOAT or task.probes_floats


COMBINATIONS = [(name, arm) for name in task_names() for arm in ARMS if supports(get_task(name), ARMS[arm])]


@contextlib.contextmanager
def no_findings() -> Iterator[None]:
    """Fail on any warning inside but ``EXPECTED_NOTICES``: gymnasium's checker reports many of its
    findings (an observation outside its space, a non-float reward) as warnings, not errors."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    found = [str(w.message) for w in caught if not any(note in str(w.message) for note in EXPECTED_NOTICES)]
    assert not found, found


def training_env(task: Task, arm: ArmSpec) -> tuple[gym.Env, DummyVecEnv]:
    """The first env of a smoke-sized run of ``task`` under ``arm`` (the simulated VLM), as
    ``make_train_env`` builds it, and its VecEnv (to close)."""
    ppo = dataclasses.replace(preset_of(task, "smoke"), n_envs=1)
    client = build_client(VLMConfig(backend="sim", use_cache=False), reader=task.reader) if arm.uses_vlm else None
    venv, _ = make_train_env(arm, ppo, task.default_shaping(), client, seed=0, task=task)
    base = venv.venv if isinstance(venv, VecNormalize) else venv
    assert isinstance(base, DummyVecEnv)
    return base.envs[0], base


@pytest.mark.parametrize(("task_name", "arm_name"), COMBINATIONS)
def test_both_checkers_pass_on_the_training_env_of_every_task_and_arm(task_name: str, arm_name: str) -> None:
    """SB3's Monitor is no ``RecordConstructorArgs``, so the stack's spec cannot build it again: the
    render and close checks (both ``env.spec.make()``) are run on the bare env below instead."""
    task = get_task(task_name)
    env, venv = training_env(task, ARMS[arm_name])
    assert isinstance(env, EpisodeStatistics) and env.success == task.success
    try:
        with no_findings():
            gymnasium_check_env(env, skip_render_check=True, skip_close_check=True)
            sb3_check_env(env, warn=True)
    finally:
        venv.close()


@pytest.mark.parametrize("task_name", task_names())
def test_both_checkers_pass_on_the_bare_env_and_its_spec_makes_it_again(task_name: str) -> None:
    task = get_task(task_name)
    env = task.make_env()
    again = env.spec.make() if env.spec is not None else None
    try:
        with no_findings():
            gymnasium_check_env(env)  # with the render check of every declared mode and the close check
            sb3_check_env(env, warn=True)
        assert again is not None, f"{task_name}: its env has no spec (build it with gym.make)"
        assert str(again) == str(env), "the same wrappers, in the same order"
        assert again.observation_space == env.observation_space and again.action_space == env.action_space
        first, _ = env.reset(seed=7)
        second, _ = again.reset(seed=7)
        np.testing.assert_array_equal(first, second)
    finally:
        env.close()
        if again is not None:
            again.close()
