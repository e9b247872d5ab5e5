"""Acrobot-v1 as a task: the dense term from the observation, the label map, the config."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.tasks.acrobot import ACROBOT, acrobot_dense, tip_height_of_obs
from vlmrl_cli.tasks.acrobot_scene import label_of_state, tip_height
from vlmrl_cli.training.config import RunConfig

angles = st.floats(-4 * math.pi, 4 * math.pi, allow_nan=False)


@given(angles, angles)
def test_the_tip_height_of_the_observation_is_the_one_of_the_angles(t1: float, t2: float) -> None:
    obs = np.array([math.cos(t1), math.sin(t1), math.cos(t2), math.sin(t2), 0.0, 0.0])
    assert tip_height_of_obs(obs) == pytest.approx(tip_height(t1, t2), abs=1e-9)
    assert acrobot_dense(obs, 2.0, 0.4) == pytest.approx(max(0.0, 2.0 * (tip_height(t1, t2) / 2 + 0.4)), abs=1e-9)


def test_the_env_observation_gives_the_states_height() -> None:
    env = gym.make("Acrobot-v1")
    sim: Any = env.unwrapped
    obs, _ = env.reset(seed=1)
    for _ in range(50):
        obs, *_ = env.step(env.action_space.sample())
        state = sim.state
        assert tip_height_of_obs(obs) == pytest.approx(tip_height(float(state[0]), float(state[1])), abs=1e-5)
    assert ACROBOT.truth(sim) == label_of_state(sim.state)
    env.close()


def test_an_acrobot_run_takes_the_tasks_labels_and_presets() -> None:
    cfg = RunConfig.from_sources(None, {"task": "acrobot", "arms": ["hybrid"], "seeds": [0]})
    job = cfg.jobs()[0]
    assert cfg.preset == "zoo" and job.ppo.n_steps == 256 and job.ppo.timesteps == 1_000_000
    assert [label for label, _ in job.shaping.label_potentials] == list(ACROBOT.milestones.labels)
    assert job.identity()["task"] == "acrobot"
    changed = RunConfig.from_sources(None, {"task": "acrobot", "arms": ["hybrid"], "seeds": [0]}, [
        "shaping.label_potentials={HIGH_SWING = 0.5}"])  # the labels it changes; the others keep acrobot's
    assert dict(changed.jobs()[0].shaping.label_potentials) == {"HANGING": 0.0, "LOW_SWING": 0.2, "HIGH_SWING": 0.5,
                                                              "ABOVE_BAR": 1.0}
    assert changed.jobs()[0].config_hash != job.config_hash


@pytest.mark.parametrize(("sets", "words"), [
    (['shaping.label_potentials=[["HANGING", 0.0], ["ABOVE_BAR", 1.0]]'], "no potential for LOW_SWING"),
    (["shaping.label_potentials={GOAL = 1.0}"], "unknown label 'GOAL'"),
])
def test_a_label_map_that_does_not_fit_acrobot_is_refused(sets: list[str], words: str) -> None:
    with pytest.raises(BadInput, match=words):
        RunConfig.from_sources(None, {"task": "acrobot"}, sets)


def test_the_float_arm_is_refused_off_mountain_car() -> None:
    with pytest.raises(BadInput, match="asks the VLM for a number"):
        RunConfig.from_sources(None, {"task": "acrobot", "arms": ["vision-float"]})
