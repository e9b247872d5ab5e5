"""The PPO learner of one run (``training.model``)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from vlmrl_cli.shaping.arms import ARMS
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR
from vlmrl_cli.training.envs import make_train_env
from vlmrl_cli.training.model import make_model
from vlmrl_cli.training.presets import preset_of


def test_learning_leaves_nothing_in_the_temp_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """SB3's default logger makes an ``SB3-<date-time>`` folder in the temp folder on every
    ``learn()``: ``vlmrl verify`` and the tests left hundreds of them behind."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    ppo = preset_of(MOUNTAIN_CAR, "smoke")
    venv, _ = make_train_env(ARMS["baseline"], ppo, ShapingConfig(), None, seed=0, task=MOUNTAIN_CAR)
    try:
        model = make_model(ppo, venv, seed=0)
        model.learn(total_timesteps=ppo.n_steps * ppo.n_envs)
        assert model.num_timesteps == ppo.n_steps * ppo.n_envs
    finally:
        venv.close()
    # (torch may keep its own compile cache there: torchinductor_<user>)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith("SB3-")] == []
