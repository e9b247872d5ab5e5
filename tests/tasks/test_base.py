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
    camera = task.make_camera(task.default_shaping())
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
