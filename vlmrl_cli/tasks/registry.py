"""Find a task by name: a built-in one, an entry point of the ``vlmrl.tasks`` group (a package
declaring ``[project.entry-points."vlmrl.tasks"]``), or ``package.module:NAME`` in the user's code.

A name read from a file (a config file, an export, a store's tags) resolves through the registry
alone (``get_task``: built-in and installed tasks); a module is imported only when the user names
it with ``--task`` on the command line (``import_task``, through ``command_tasks``), and only a
module whose source, read first without running it, imports ``vlmrl_cli`` and binds ``NAME``
(``--task this:x`` prints no Zen of Python; ``--task mlflow.__main__:x`` runs no MLflow).

What ``NAME`` (or an entry point) names must be a ``Task``, or a plain function marked with
``@task_factory`` that returns one. The object is checked before anything is called: vlmrl calls
no other object it is pointed at.

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
#: The attribute ``task_factory`` sets on a function: the one mark that lets vlmrl call what a
#: ``--task`` string or an entry point names.
FACTORY_MARK = "__vlmrl_task_factory__"
#: What a ``--task package.module:NAME`` or an entry point may name, said in every refusal.
_ACCEPTED = ("give a Task, or a function marked @task_factory (vlmrl_cli.tasks.registry) that returns one; "
             "vlmrl calls nothing else")

_Factory = TypeVar("_Factory", bound=Callable[[], Task])


def task_factory(fn: _Factory) -> _Factory:
    """Mark ``fn``, a function of no arguments that returns a ``Task``, as a task factory: a
    ``--task package.module:fn`` or an entry point naming it calls it. Nothing unmarked is called.

    Example:
        >>> @task_factory
        ... def acrobot_again() -> Task:
        ...     return get_task("acrobot")
        >>> _resolved(acrobot_again, "'doc:acrobot_again'").env_id
        'Acrobot-v1'
    """
    if not inspect.isfunction(fn):
        raise TypeError(f"@task_factory marks a function (def), not a {type(fn).__name__}")
    setattr(fn, FACTORY_MARK, True)
    return fn


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


def _pusher() -> Task:
    """Pusher-v5 (the ``pusher`` extra: MuJoCo): a ``BadInput`` in one line where MuJoCo or a
    headless OpenGL is missing."""
    from vlmrl_cli.tasks.pusher import pusher_task

    task: Task = pusher_task()
    return task


BUILTIN: dict[str, Callable[[], Task]] = {
    "mountain-car": _mountain_car,
    "mountain-car-continuous": _mountain_car_continuous,
    "acrobot": _acrobot,
    "minigrid-doorkey": _minigrid_doorkey,
    "pusher": _pusher,
}


def recorded_task(name: object) -> str:
    """The task a run recorded (its ``vlmrl.task`` tag, its config's ``task``): runs from before
    tasks existed record none; they are the built-in task that keeps its name out of its config
    hashes for them (the paper's task, ``paper_task``).

    Example:
        >>> recorded_task("acrobot"), recorded_task(None)
        ('acrobot', 'mountain-car')
    """
    if name:
        return str(name)
    return paper_task().name


def builtin_task(name: str) -> Task:
    """The built-in task ``name`` (no module or entry point is loaded): the lookup of a config
    built without the command's registry; anything else is a ``BadInput`` saying so.

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
    """The built-in or installed task called ``name``; anything unknown or broken is a ``BadInput``
    saying why. A ``module:NAME`` is refused here: this is the lookup of names read from files.

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
    """The task lookup of a command: the ``module:NAME`` tasks the user named on its command line
    (``specs``; other names and None are skipped) imported once, now (``import_task``), and every
    other name through the registry (``get_task``). A file that names the same ``module:NAME``
    gets the task the command line already loaded; one that names another module is refused.

    Example:
        >>> lookup = command_tasks(["acrobot", None])
        >>> lookup("acrobot").env_id
        'Acrobot-v1'
    """
    return CommandTasks(tuple(spec for spec in specs if spec is not None and ":" in spec))


class CommandTasks:
    """``command_tasks``' lookup; it crosses to a spawned worker as its specs, which the worker
    imports again (the command line named them)."""

    def __init__(self, specs: tuple[str, ...]) -> None:
        self.specs = specs
        self._named = {spec: import_task(spec) for spec in specs}

    def __call__(self, ref: str) -> Task:
        return self._named[ref] if ref in self._named else get_task(ref)

    def __reduce__(self) -> tuple[type[CommandTasks], tuple[tuple[str, ...]]]:
        return (CommandTasks, (self.specs,))


def job_task(ref: str) -> Task:
    """The task of a job this machine's command built (a sweep's or verify's worker resolves it at
    the job's entry): the command already loaded ``ref`` through ``command_tasks``, so a
    ``module:NAME`` is imported here as it was there."""
    return import_task(ref) if ":" in ref else get_task(ref)


def import_task(spec: str) -> Task:
    """The task ``package.module:NAME`` of the user's own code. The module's source is found on
    ``sys.path`` and read before anything runs: a module that does not import ``vlmrl_cli`` or does
    not bind ``NAME`` at its top level is refused unimported; then the module (and its packages)
    is imported and ``NAME`` checked (``_resolved``)."""
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
    """The source file of ``module_name`` (``a.b`` -> ``a/b.py`` or ``a/b/__init__.py``) in the first
    folder of ``path`` (``sys.path``; '' is the current folder) that has it, found without importing
    anything (``importlib.util.find_spec`` imports a dotted name's packages); None for a module with
    no source file (built in, compiled, zipped)."""
    parts = module_name.split(".")
    for entry in sys.path if path is None else path:
        base = Path(entry or ".").joinpath(*parts)
        for candidate in (base.with_name(base.name + ".py"), base / "__init__.py"):
            if candidate.is_file():
                return candidate
    return None


def _source_problem(source: Path, name: str) -> str | None:
    """Why the module source ``source`` is not a task module offering ``name``, or None: it must
    import ``vlmrl_cli`` and bind ``name`` at its top level. Read as text and parsed, never run."""
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
    """Whether ``value`` is a plain function marked with ``@task_factory``; read from the
    function's own ``__dict__``, so that checking runs none of the object's code.

    Example:
        >>> import os
        >>> is_task_factory(os.system), is_task_factory(task_factory(lambda: get_task("acrobot")))
        (False, True)
    """
    return inspect.isfunction(value) and value.__dict__.get(FACTORY_MARK) is True


def _resolved(value: object, where: str) -> Task:
    """``value`` if it is a ``Task``, the ``Task`` a marked factory returns, else ``BadInput``:
    the type is checked before anything is called."""
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
