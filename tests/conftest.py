"""Test-wide settings: headless matplotlib and pygame backends (torch's threads are set by the nox
session's OMP_NUM_THREADS/MKL_NUM_THREADS, and by each training worker itself), and the order in
which pytest-xdist hands files to its workers."""

from __future__ import annotations

import os
from collections import Counter

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
# Pusher's MuJoCo frames: Mesa's EGL, chosen before mujoco is imported (it sets PYOPENGL_PLATFORM
# itself where unset); the task sets the same where nothing is set (tasks/pusher_scene.py)
os.environ.setdefault("MUJOCO_GL", "egl")
if os.environ["MUJOCO_GL"] in ("egl", "osmesa"):  # PyOpenGL's platform must match MuJoCo's back end
    os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
# Ray's driver replaces builtins.print when it relays a worker's tqdm output (ray.experimental.
# tqdm_ray): a process-wide change that outlives the Ray tests in their xdist worker, after which
# `print` is a Python function (test_task_factory_marks_functions_only saw it). Not here.
os.environ.setdefault("RAY_TQDM_PATCH_PRINT", "0")


def _file(item: pytest.Item) -> str:
    return item.nodeid.split("::", 1)[0]


def heaviest_files_first(items: list[pytest.Item]) -> list[pytest.Item]:
    """The items, files with the most `slow` tests (those that train, start Ray or a server) first,
    the others in collection order, each file's tests kept together and in order.

    `--dist loadfile` hands out whole files in this order (the nox session turns xdist's own
    reordering, by number of tests, off), so that the long files start first and the quick ones fill
    the gaps at the end: longest-first scheduling, instead of a long file that starts last."""
    slow = Counter(_file(item) for item in items if item.get_closest_marker("slow"))
    first = {name: n for n, name in enumerate(dict.fromkeys(_file(item) for item in items))}
    return sorted(items, key=lambda item: (-slow[_file(item)], first[_file(item)]))


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    items[:] = heaviest_files_first(items)
