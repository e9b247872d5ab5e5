"""MountainCar-v0 as the first task (unchanged) and MountainCarContinuous-v0 (its reader and presets)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from vlmrl_cli.tasks.mountain_car.reader import WheelReader
from vlmrl_cli.tasks.mountain_car.render import FrameRenderer
from vlmrl_cli.tasks.mountain_car.task import (
    CONTINUOUS_ENV_ID,
    CONTINUOUS_GOAL,
    MOUNTAIN_CAR,
    MOUNTAIN_CAR_CONTINUOUS,
    ContinuousZoneReader,
    geometry,
)
from vlmrl_cli.tasks.mountain_car.task import MOUNTAIN_CAR_SCENE as MC_SCENE
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.training.config import RunConfig
from vlmrl_cli.training.presets import preset_of


def test_mountain_car_is_the_paper_task_as_before() -> None:
    assert MOUNTAIN_CAR.scene is MC_SCENE and isinstance(MOUNTAIN_CAR.reader, WheelReader)
    assert MOUNTAIN_CAR.probes_floats and not MOUNTAIN_CAR.name_in_identity and MOUNTAIN_CAR.paper is not None
    assert MOUNTAIN_CAR.thresholds == (-190.0, -160.0, -130.0) and MOUNTAIN_CAR.max_steps == 200
    job = RunConfig.from_sources(None, {"arms": ["hybrid"], "seeds": [0]}).jobs()[0]
    assert "task" not in job.identity()  # MountainCar's hashes predate tasks (test_pinned_hashes.py)
    assert job.preset == "paper" and job.ppo == preset_of(get_task("mountain-car"), "paper")


def test_the_continuous_reader_reads_the_true_zone_off_the_pixels() -> None:
    reader = ContinuousZoneReader()
    xs = np.linspace(geometry.MIN_POSITION, geometry.MAX_POSITION, 61)
    env: Any = MOUNTAIN_CAR_CONTINUOUS.make_env().unwrapped
    env.reset(seed=0)
    wrong = []
    with FrameRenderer(CONTINUOUS_ENV_ID) as renderer:
        for x in xs:
            env.state = np.array([x, 0.0])
            truth = MOUNTAIN_CAR_CONTINUOUS.truth(env)
            edges = (*geometry.ZONE_EDGES[:-1], CONTINUOUS_GOAL)
            if min(abs(x - e) for e in edges) < 0.01:  # within about 3 px of an edge: either side is fair
                continue
            if reader.read(renderer.render(float(x)).pixels) != truth:
                wrong.append(round(float(x), 3))
    assert wrong == []
    assert MOUNTAIN_CAR_CONTINUOUS.truth(type("S", (), {"state": np.array([0.46, 0.0])})()) == "GOAL"
    assert MOUNTAIN_CAR.truth(type("S", (), {"state": np.array([0.46, 0.0])})()) == "NEAR_GOAL"


def test_the_continuous_zoo_preset_is_rl_zoos() -> None:
    zoo = preset_of(get_task("mountain-car-continuous"), "zoo")
    assert (zoo.n_envs, zoo.n_steps, zoo.gamma, zoo.learning_rate, zoo.use_sde, zoo.log_std_init, zoo.ortho_init) == (
        1, 8, 0.9999, 7.77e-05, True, -3.29, False)
    assert zoo.timesteps == 20_000
    cfg = RunConfig.from_sources(None, {"task": "mountain-car-continuous", "arms": ["baseline"], "seeds": [0]})
    assert cfg.preset == "zoo" and cfg.ppo_config == zoo  # a task starts from its own default preset
    assert cfg.jobs()[0].identity()["ppo"]["use_sde"] is True


@pytest.mark.parametrize("preset", ["paper", "paper-unreliable"])
def test_mountain_car_presets_are_refused_for_the_continuous_task(preset: str) -> None:
    from vlmrl_cli.core.errors import BadInput

    with pytest.raises(BadInput, match="for task mountain-car-continuous"):
        RunConfig.from_sources(None, {"task": "mountain-car-continuous", "preset": preset})
