"""Find a task by name: a built-in one, ``package.module:NAME`` in the user's code, or an entry
point of the ``vlmrl.tasks`` group (a package declaring ``[project.entry-points."vlmrl.tasks"]``).

Example:
    >>> get_task("mountain-car").env_id
    'MountainCar-v0'
    >>> try:
    ...     get_task("acrobat")
    ... except BadInput as exc:
    ...     print(str(exc)[:52])
    unknown task 'acrobat' (did you mean 'acrobot'?); ch
"""

from __future__ import annotations

import importlib
import importlib.metadata
from collections.abc import Callable

from vlmrl_cli.core.errors import BadInput, did_you_mean
from vlmrl_cli.tasks.base import Task

ENTRY_POINT_GROUP = "vlmrl.tasks"


def _mountain_car() -> Task:
    from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR

    return MOUNTAIN_CAR


def _mountain_car_continuous() -> Task:
    from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR_CONTINUOUS

    return MOUNTAIN_CAR_CONTINUOUS


def _acrobot() -> Task:
    from vlmrl_cli.tasks.acrobot import ACROBOT

    return ACROBOT


def _minigrid_doorkey() -> Task:
    from vlmrl_cli.tasks.minigrid_doorkey import DOORKEY

    return DOORKEY


BUILTIN: dict[str, Callable[[], Task]] = {
    "mountain-car": _mountain_car,
    "mountain-car-continuous": _mountain_car_continuous,
    "acrobot": _acrobot,
    "minigrid-doorkey": _minigrid_doorkey,
}


def recorded_task(name: object) -> str:
    """The task a run recorded (its ``vlmrl.task`` tag, its config's ``task``): runs from before
    tasks existed record none; they are the built-in task that keeps its name out of its config
    hashes for them (``Task.name_in_identity`` False).

    Example:
        >>> recorded_task("acrobot"), recorded_task(None)
        ('acrobot', 'mountain-car')
    """
    if name:
        return str(name)
    return next(key for key, load in BUILTIN.items() if not load().name_in_identity)


def task_names() -> list[str]:
    """The built-in tasks and the installed entry points, in that order."""
    installed = [ep.name for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP) if ep.name not in BUILTIN]
    return [*BUILTIN, *sorted(installed)]


def get_task(name: str) -> Task:
    """The task called ``name``; anything unknown or broken is a ``BadInput`` saying why."""
    if name in BUILTIN:
        return BUILTIN[name]()
    if ":" in name:
        return _from_module(name)
    for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        if ep.name == name:
            return _checked(_load(ep.load, f"entry point '{name}' ({ep.value})"), name)
    known = task_names()
    raise BadInput(f"unknown task '{name}'{did_you_mean(name, known)}; choose from {', '.join(known)}, "
                   "or give package.module:NAME")


def _from_module(spec: str) -> Task:
    module_name, _, attr = spec.partition(":")
    if not module_name or not attr:
        raise BadInput(f"task '{spec}': give package.module:NAME, e.g. mytasks.pendulum:TASK")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        raise BadInput(f"task '{spec}': cannot import {module_name} ({exc}); is it on PYTHONPATH or installed?") \
            from None
    except Exception as exc:  # the user's module failed while importing: say where
        raise BadInput(f"task '{spec}': importing {module_name} failed: {type(exc).__name__}: {exc}") from None
    if not hasattr(module, attr):
        raise BadInput(f"task '{spec}': {module_name} has no {attr}")
    return _checked(_load(lambda: getattr(module, attr), f"{spec}"), spec)


def _load(get: Callable[[], object], where: str) -> object:
    try:
        value = get()
        return value() if callable(value) and not isinstance(value, Task) else value
    except BadInput:
        raise
    except Exception as exc:
        raise BadInput(f"task {where} failed to load: {type(exc).__name__}: {exc}") from None


def _checked(value: object, name: str) -> Task:
    if not isinstance(value, Task):
        raise BadInput(f"task '{name}' is a {type(value).__name__}, not a vlmrl_cli.tasks.base.Task")
    return value
