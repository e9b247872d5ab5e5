"""``Task`` itself: its env and camera leave the process's settings alone, and its success rule is
the one its plug-in gives."""

from __future__ import annotations

import dataclasses
import os

import numpy as np
import pytest

from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR
from vlmrl_cli.tasks.registry import get_task, task_names


@pytest.mark.parametrize("name", task_names())
def test_a_rendering_env_and_its_camera_leave_os_environ_unchanged(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The video driver is the process's choice (``vlmrl``'s entry point, the sweep's workers, this
    suite's conftest), not a side effect of making an env."""
    monkeypatch.delenv("SDL_VIDEODRIVER", raising=False)
    before = dict(os.environ)
    task = get_task(name)
    env = task.make_env(render_mode="rgb_array")
    camera = task.camera.make(task.default_shaping())
    try:
        env.reset(seed=0)
        assert np.asarray(env.render()).ndim == 3
        assert camera.look(env.unwrapped).frame().pixels.ndim == 3
    finally:
        camera.close()
        env.close()
    assert dict(os.environ) == before


def test_the_default_rule_is_terminated_within_the_time_limit() -> None:
    car = get_task("mountain-car")
    assert car.success_rule is None
    assert car.success(True, 120) and car.success(True, car.max_steps)
    assert not car.success(True, car.max_steps + 1) and not car.success(False, car.max_steps)


def test_a_tasks_own_rule_replaces_the_default() -> None:
    calls: list[tuple[bool, int]] = []

    def survived(terminated: bool, length: int) -> bool:
        calls.append((terminated, length))
        return not terminated and length >= 200

    survive = dataclasses.replace(MOUNTAIN_CAR, name="survive-car", success_rule=survived)
    assert survive.success(False, 200) and not survive.success(True, 120)
    assert calls == [(False, 200), (True, 120)]
    assert MOUNTAIN_CAR.success(True, 120) and MOUNTAIN_CAR.success_rule is None  # the original is untouched


def _required(cls: type) -> list[str]:
    return [f.name for f in dataclasses.fields(cls)
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING]


def test_a_task_needs_at_most_twelve_fields_and_no_flag_means_mountain_car() -> None:
    """What every task must state is short; the rest are defaults or capability values, and none
    is a boolean that only MountainCar-v0 sets."""
    from vlmrl_cli.tasks.base import Task

    assert len(_required(Task)) <= 12, _required(Task)
    flags = [f.name for f in dataclasses.fields(Task) if f.type in ("bool", bool)]
    assert flags == []


@pytest.mark.parametrize("name", task_names())
def test_only_the_papers_task_keeps_its_name_out_of_its_hashes(name: str) -> None:
    task = get_task(name)
    assert task.name_in_identity == (task.paper is None)
    assert (task.paper is not None) == (name == "mountain-car")


def test_a_capability_turns_its_feature_on_and_its_absence_off() -> None:
    from vlmrl_cli.tasks.capabilities import Hover

    bare = dataclasses.replace(MOUNTAIN_CAR, hover=None, caption=None)
    assert not bare.hover_diagnostic and bare.hover_from is None
    on = dataclasses.replace(bare, hover=Hover(lambda obs: float(obs[0]), start=0.1))
    assert on.hover_diagnostic and on.hover_from == 0.1
