"""Find a task by name: built in, an entry point of the ``vlmrl.tasks`` group, or (named on the
command line only) ``package.module:NAME``, whose source is read before it is imported. What a name
points at must be a ``Task`` or a function marked ``@task_factory``. See docs/tasks.md, "Add a task".

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

import ast
import importlib
import importlib.metadata
import inspect
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TypeVar

from vlmrl_cli.core.errors import BadInput, did_you_mean
from vlmrl_cli.tasks.base import Task, TaskLookup

ENTRY_POINT_GROUP = "vlmrl.tasks"
#: The attribute ``task_factory`` sets: the one mark that lets vlmrl call what a ``--task`` names.
FACTORY_MARK = "__vlmrl_task_factory__"
#: What a ``--task package.module:NAME`` or an entry point may name, said in every refusal.
_ACCEPTED = ("give a Task, or a function marked @task_factory (vlmrl_cli.tasks.registry) that returns one; "
             "vlmrl calls nothing else")

_Factory = TypeVar("_Factory", bound=Callable[[], Task])


def task_factory(fn: _Factory) -> _Factory:
    """Mark ``fn``, a function of no arguments returning a ``Task``, as one that ``--task`` may call."""
    if not inspect.isfunction(fn):
        raise TypeError(f"@task_factory marks a function (def), not a {type(fn).__name__}")
    setattr(fn, FACTORY_MARK, True)
    return fn


def _builtin(module: str, name: str) -> Callable[[], Task]:
    """A loader of the task ``name`` of ``module`` (called, for a factory), imported when first asked for."""
    def load() -> Task:
        value = getattr(importlib.import_module(f"vlmrl_cli.tasks.{module}"), name)
        return value if isinstance(value, Task) else value()

    return load


BUILTIN: dict[str, Callable[[], Task]] = {
    "mountain-car": _builtin("mountain_car", "MOUNTAIN_CAR"),
    "mountain-car-continuous": _builtin("mountain_car", "MOUNTAIN_CAR_CONTINUOUS"),
    "acrobot": _builtin("acrobot", "ACROBOT"),
    "minigrid-doorkey": _builtin("minigrid_doorkey", "DOORKEY"),
    "pusher": _builtin("pusher", "pusher_task"),  # MuJoCo and a headless GL, checked: else BadInput
}


def recorded_task(name: object) -> str:
    """The task a run recorded (``vlmrl.task``); runs from before tasks record none: the paper's task.

    Example:
        >>> recorded_task("acrobot"), recorded_task(None)
        ('acrobot', 'mountain-car')
    """
    if name:
        return str(name)
    return paper_task().name


def builtin_task(name: str) -> Task:
    """The built-in task ``name`` (the lookup of a config built without the command's); else ``BadInput``.

    Example:
        >>> builtin_task("acrobot").env_id
        'Acrobot-v1'
    """
    if name in BUILTIN:
        return BUILTIN[name]()
    if ":" in name or name in task_names():
        raise BadInput(f"task '{name}' is not built in; this config was built without the command's task "
                       "registry (pass tasks=get_task)")
    return get_task(name)  # unknown: its BadInput names the tasks there are


def paper_task() -> Task:
    """The built-in task the paper reports (the one with a ``PaperTask``: MountainCar-v0).

    Example:
        >>> paper_task().name, paper_task().paper.budget
        ('mountain-car', 300000)
    """
    return next(task for task in (load() for load in BUILTIN.values()) if task.paper is not None)


def task_names() -> list[str]:
    """The built-in tasks and the installed entry points, in that order."""
    installed = [ep.name for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP) if ep.name not in BUILTIN]
    return [*BUILTIN, *sorted(installed)]


def get_task(name: str) -> Task:
    """The built-in or installed task ``name``, else ``BadInput``; a ``module:NAME`` (read from a file) is refused.

    Example:
        >>> try:
        ...     get_task("this:x")
        ... except BadInput as exc:
        ...     print(str(exc)[:60])
        task 'this:x' names a Python module; vlmrl imports a module
    """
    if name in BUILTIN:
        return BUILTIN[name]()
    if ":" in name:
        raise BadInput(f"task '{name}' names a Python module; vlmrl imports a module only when you name it "
                       "with --task on the command line, never from a file, an export or a store")
    for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        if ep.name == name:
            where = f"entry point '{name}' ({ep.value})"
            return _resolved(_load(ep.load, where), where)
    known = task_names()
    raise BadInput(f"unknown task '{name}'{did_you_mean(name, known)}; choose from {', '.join(known)}, "
                   "or give package.module:NAME with --task")


def command_tasks(specs: Iterable[str | None] = ()) -> TaskLookup:
    """A command's task lookup: the ``module:NAME`` tasks among ``specs`` (its command line) imported
    once, now; every other name through ``get_task`` (a file naming another module is refused).
    """
    return CommandTasks(tuple(spec for spec in specs if spec is not None and ":" in spec))


class CommandTasks:
    """``command_tasks``' lookup; a spawned worker gets its specs and imports them again."""

    def __init__(self, specs: tuple[str, ...]) -> None:
        self.specs = specs
        self._named = {spec: import_task(spec) for spec in specs}

    def __call__(self, ref: str) -> Task:
        return self._named[ref] if ref in self._named else get_task(ref)

    def __reduce__(self) -> tuple[type[CommandTasks], tuple[tuple[str, ...]]]:
        return (CommandTasks, (self.specs,))


def job_task(ref: str) -> Task:
    """The task of a job this machine's command built; a ``module:NAME`` is imported as it was there."""
    return import_task(ref) if ":" in ref else get_task(ref)


def import_task(spec: str) -> Task:
    """The task ``package.module:NAME`` of the user's code; a module whose source does not import
    ``vlmrl_cli`` and bind ``NAME`` at its top level is refused unimported."""
    module_name, _, attr = spec.partition(":")
    if not module_name or not attr or not all(part.isidentifier() for part in (*module_name.split("."), attr)):
        raise BadInput(f"task '{spec}': give package.module:NAME, e.g. mytasks.pendulum:TASK")
    source = module_source(module_name)
    if source is None:
        raise BadInput(f"task '{spec}': no Python source file {module_name.replace('.', '/')}.py on the path; "
                       "is it on PYTHONPATH (or in the current folder)?")
    problem = _source_problem(source, attr)
    if problem:
        raise BadInput(f"task '{spec}': {source} {problem}; it is not a vlmrl task module, and nothing of it ran")
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:  # the user's module failed while importing: say where
        raise BadInput(f"task '{spec}': importing {module_name} failed: {type(exc).__name__}: {exc}") from None
    if not hasattr(module, attr):
        raise BadInput(f"task '{spec}': {module_name} has no {attr}")
    return _resolved(_load(lambda: getattr(module, attr), f"'{spec}'"), f"'{spec}'")


def module_source(module_name: str, path: Iterable[str] | None = None) -> Path | None:
    """The source file of ``module_name`` on ``path`` (``sys.path``), found without importing anything
    (``find_spec`` imports a dotted name's packages); None where it has none."""
    parts = module_name.split(".")
    for entry in sys.path if path is None else path:
        base = Path(entry or ".").joinpath(*parts)
        for candidate in (base.with_name(base.name + ".py"), base / "__init__.py"):
            if candidate.is_file():
                return candidate
    return None


def _source_problem(source: Path, name: str) -> str | None:
    """Why ``source`` (parsed, never run) does not import ``vlmrl_cli`` and bind ``name``, or None."""
    try:
        tree = ast.parse(source.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, SyntaxError, ValueError) as exc:
        return f"cannot be read as Python ({type(exc).__name__})"
    imports_vlmrl = any(
        (isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "vlmrl_cli")
        or (isinstance(node, ast.Import) and any(a.name.split(".")[0] == "vlmrl_cli" for a in node.names))
        for node in ast.walk(tree))
    if not imports_vlmrl:
        return "does not import vlmrl_cli"
    bound = set()
    for node in tree.body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            bound.add(node.name)
        elif isinstance(node, ast.Assign | ast.AnnAssign | ast.AugAssign):
            for target in node.targets if isinstance(node, ast.Assign) else [node.target]:
                bound |= {n.id for n in ast.walk(target) if isinstance(n, ast.Name)}
        elif isinstance(node, ast.Import | ast.ImportFrom):
            bound |= {(a.asname or a.name).split(".")[0] for a in node.names}
    return None if name in bound else f"binds no top-level {name}"


def _load(get: Callable[[], object], where: str) -> object:
    """The object ``get`` fetches (an attribute, an entry point's target), never called."""
    try:
        return get()
    except Exception as exc:
        raise BadInput(f"task {where} failed to load: {type(exc).__name__}: {exc}") from None


def is_task_factory(value: object) -> bool:
    """Whether ``value`` is a function marked ``@task_factory`` (read from its ``__dict__``: no code runs).

    Example:
        >>> import os
        >>> is_task_factory(os.system), is_task_factory(task_factory(lambda: get_task("acrobot")))
        (False, True)
    """
    return inspect.isfunction(value) and value.__dict__.get(FACTORY_MARK) is True


def _resolved(value: object, where: str) -> Task:
    """``value`` if a ``Task``, what a marked factory returns, else ``BadInput`` (checked before any call)."""
    if isinstance(value, Task):
        return value
    if not is_task_factory(value):
        kind = "function not marked @task_factory" if inspect.isfunction(value) else type(value).__name__
        raise BadInput(f"task {where} is a {kind}, not a vlmrl_cli.tasks.base.Task; {_ACCEPTED}")
    assert callable(value)  # a function, checked above
    try:
        made = value()
    except BadInput:
        raise
    except Exception as exc:  # the user's factory failed: say where
        raise BadInput(f"task {where}: its factory failed: {type(exc).__name__}: {exc}") from None
    if not isinstance(made, Task):
        raise BadInput(f"task {where}: its factory returned a {type(made).__name__}, not a "
                       "vlmrl_cli.tasks.base.Task")
    return made
