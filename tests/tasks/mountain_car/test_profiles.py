"""MountainCar's own simulated-VLM profile (``Task.sim_profiles``): llava-table1, offered by its task
alone, with the knob values (so the config hashes and cache keys) it had in vlm/config.py."""

from __future__ import annotations

import pytest

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR, MOUNTAIN_CAR_CONTINUOUS
from vlmrl_cli.tasks.mountain_car.profiles import LLAVA_TABLE1
from vlmrl_cli.training.config import RunConfig
from vlmrl_cli.vlm.config import SIM_PROFILES, sim_profiles


def test_llava_table1_is_mountain_cars_with_its_old_values() -> None:
    assert MOUNTAIN_CAR.sim_profiles == (LLAVA_TABLE1,) and "llava-table1" not in SIM_PROFILES
    assert dict(LLAVA_TABLE1.knobs) == {
        "flicker": 0.0, "float_noise": 0.005, "float_anchor": 0.38, "mcq_bottom_halfwidth": 0.45,
        "box_failure": 0.5, "box_noise_px": 10.0, "box_anchor_x": 0.2, "patch_px": 56,
    }
    assert list(sim_profiles(MOUNTAIN_CAR)) == ["ideal", "default", "llava-table1"]
    # the continuous car's reader reads no number: the profile's knobs would mean nothing to it
    assert list(sim_profiles(MOUNTAIN_CAR_CONTINUOUS)) == ["ideal", "default"]


def test_a_run_finds_the_profile_through_its_task() -> None:
    cfg = RunConfig.from_sources(None, {"arms": ["hybrid"], "seeds": [0]}, ['vlm.sim.profile="llava-table1"',
                                                                            "vlm.sim.flicker=0.3"])
    sim = cfg.vlm.sim
    assert (sim.profile, sim.flicker, sim.float_anchor, sim.mcq_bottom_halfwidth, sim.box_anchor_x) == (
        "llava-table1", 0.3, 0.38, 0.45, 0.2)


@pytest.mark.parametrize("task", ["acrobot", "mountain-car-continuous"])
def test_another_tasks_run_may_not_name_it(task: str) -> None:
    with pytest.raises(BadInput, match=f"unknown simulated-VLM profile 'llava-table1' for task {task}; "
                                       "choose from ideal, default"):
        RunConfig.from_sources(None, {"task": task, "arms": ["hybrid"], "seeds": [0]},
                               ['vlm.sim.profile="llava-table1"'])
