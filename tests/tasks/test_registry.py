"""Finding tasks: built-in names, a user's ``package.module:NAME`` (the docs' example, run as a
smoke sweep; the grid-world example read frame by frame and run through study and evaluate), and every
way a name can be wrong."""

from __future__ import annotations

import importlib.metadata
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from vlmrl_cli.cli.app import app
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.shaping.camera import CellCamera
from vlmrl_cli.shaping.config import ShapingConfig
from vlmrl_cli.sweep.runner import SilentReporter, run_sweep
from vlmrl_cli.tasks.base import Task
from vlmrl_cli.tasks.registry import (
    BUILTIN,
    ENTRY_POINT_GROUP,
    command_tasks,
    get_task,
    import_task,
    task_factory,
    task_names,
)
from vlmrl_cli.tracking import store
from vlmrl_cli.training.config import DEFAULT_TASK, RunConfig

runner = CliRunner()
DOCS = Path(__file__).resolve().parents[2] / "docs" / "tasks.md"


def _example_code(path: str) -> str:
    """The ``python`` block of docs/tasks.md whose docstring opens with ``path``, verbatim."""
    blocks = re.findall(r"```python\n(.*?)```", DOCS.read_text(encoding="utf-8"), flags=re.S)
    found = [b for b in blocks if b.startswith(f'"""{path}:')]
    assert len(found) == 1, f"docs/tasks.md should hold one python example of {path}"
    return found[0]


def _as_user_module(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, path: str, module: str) -> Iterator[str]:
    """A docs example as ``module`` on sys.path and on the workers' PYTHONPATH."""
    (tmp_path / f"{module}.py").write_text(_example_code(path), encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", f"{tmp_path}:{':'.join(p for p in sys.path if p)}")
    yield f"{module}:TASK"
    sys.modules.pop(module, None)


@pytest.fixture
def user_module(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """The docs' first example (MountainCar seen through two milestones) as ``mytasks_valley``."""
    yield from _as_user_module(tmp_path, monkeypatch, "mytasks/valley.py", "mytasks_valley")


@pytest.fixture
def room_module(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """The docs' grid-world example (MiniGrid's empty room) as ``mytasks_room``."""
    yield from _as_user_module(tmp_path, monkeypatch, "mytasks/room.py", "mytasks_room")


def test_every_builtin_task_loads_and_mountain_car_is_the_default() -> None:
    assert DEFAULT_TASK == "mountain-car" and task_names()[:len(BUILTIN)] == list(BUILTIN)
    for name in BUILTIN:
        task = get_task(name)
        assert isinstance(task, Task) and task.name == name
        assert task.labels_problem(task.label_potentials) is None
        assert task.make_env().spec is not None


@pytest.mark.parametrize(("name", "words"), [
    ("acrobat", "did you mean 'acrobot'"),
    ("this:x", "task 'this:x' names a Python module; vlmrl imports a module only when you name it with --task on "
               "the command line, never from a file, an export or a store"),
    ("mytasks.valley:TASK", "names a Python module"),
])
def test_a_name_from_a_file_resolves_through_the_registry_alone(name: str, words: str) -> None:
    with pytest.raises(BadInput, match=re.escape(words)):
        get_task(name)


@pytest.mark.parametrize(("name", "words"), [
    ("no_such_module_xyz:TASK", "no Python source file no_such_module_xyz.py on the path"),
    ("math:pi", "no Python source file math.py"),  # compiled into the interpreter: no source to read first
    ("os:system", "os.py does not import vlmrl_cli; it is not a vlmrl task module, and nothing of it ran"),
    ("os.path:join", "no Python source file os/path.py"),
    ("this:x", "this.py does not import vlmrl_cli"),
    ("mlflow.__main__:cli", "__main__.py does not import vlmrl_cli"),
    ("vlmrl_cli.tasks.base:Task", "is a type, not a vlmrl_cli.tasks.base.Task"),
    ("vlmrl_cli.tasks.base:nothing_here", "base.py binds no top-level nothing_here"),
    (":TASK", "give package.module:NAME"),
    ("my tasks:TASK", "give package.module:NAME"),
])
def test_a_bad_task_module_says_why(name: str, words: str) -> None:
    with pytest.raises(BadInput, match=re.escape(words)):
        import_task(name)


def test_a_module_that_is_no_task_module_is_never_imported() -> None:
    # `this` prints the Zen of Python when imported; `mlflow.__main__` runs MLflow's CLI: run where a
    # regression cannot touch the suite's own process
    code = ("import sys\nfrom vlmrl_cli.core.errors import BadInput\nfrom vlmrl_cli.tasks.registry import "
            "command_tasks\nfor spec in ('this:x', 'mlflow.__main__:cli', 'os:abort'):\n    try:\n"
            "        command_tasks([spec])\n    except BadInput as exc:\n        print(exc)\n"
            "print(sorted(m for m in ('this', 'mlflow', 'mlflow.__main__') if m in sys.modules))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == 4 and all("does not import vlmrl_cli" in line for line in lines[:3]), done.stdout
    assert lines[3] == "[]" and "Zen" not in done.stdout and not done.stderr


USER_CODE = """
from vlmrl_cli.tasks.registry import get_task, task_factory

CALLS = []


@task_factory
def marked():
    CALLS.append("marked")
    return get_task("acrobot")


def unmarked():
    CALLS.append("unmarked")
    return get_task("acrobot")


@task_factory
def not_a_task():
    CALLS.append("not_a_task")
    return 42


@task_factory
def broken():
    raise RuntimeError("no such env")


class Maker:
    def __call__(self):
        CALLS.append("Maker")
        return get_task("acrobot")


instance = Maker()
"""


@pytest.fixture
def factories(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    (tmp_path / "mytasks_factories.py").write_text(USER_CODE, encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "mytasks_factories"
    sys.modules.pop("mytasks_factories", None)


def test_a_marked_factory_is_called_and_nothing_unmarked_ever_is(factories: str) -> None:
    calls = __import__(factories).CALLS
    assert import_task(f"{factories}:marked").name == "acrobot" and calls == ["marked"]
    for name, words in (("unmarked", "is a function not marked @task_factory"),
                        ("Maker", "is a type, not a vlmrl_cli.tasks.base.Task"),
                        ("instance", "is a Maker, not a vlmrl_cli.tasks.base.Task")):
        with pytest.raises(BadInput, match=re.escape(words)):
            import_task(f"{factories}:{name}")
    assert calls == ["marked"]  # the type is checked first: none of them was called
    with pytest.raises(BadInput, match=re.escape("its factory returned a int, not a vlmrl_cli.tasks.base.Task")):
        import_task(f"{factories}:not_a_task")
    with pytest.raises(BadInput, match="its factory failed: RuntimeError: no such env"):
        import_task(f"{factories}:broken")


def test_task_factory_marks_functions_only() -> None:
    with pytest.raises(TypeError, match="marks a function"):
        task_factory(print)  # type: ignore[type-var]


def test_an_entry_point_follows_the_same_rule(factories: str, monkeypatch: pytest.MonkeyPatch) -> None:
    installed = [importlib.metadata.EntryPoint(name, value, ENTRY_POINT_GROUP) for name, value in
                 (("shell", "os:system"), ("made", f"{factories}:marked"), ("plain", f"{factories}:unmarked"))]
    monkeypatch.setattr(importlib.metadata, "entry_points",
                        lambda group=None: [ep for ep in installed if ep.group == group])
    assert get_task("made").name == "acrobot" and "shell" in task_names()
    with pytest.raises(BadInput, match=re.escape("entry point 'shell' (os:system) is a builtin_function_or_method")):
        get_task("shell")
    with pytest.raises(BadInput, match="is a function not marked @task_factory"):
        get_task("plain")
    assert __import__(factories).CALLS == ["marked"]


def test_the_docs_example_task_loads_from_a_user_module(user_module: str) -> None:
    task = import_task(user_module)
    assert task.name == "valley" and task.milestones.labels == ("VALLEY", "HILL")
    cfg = RunConfig.from_sources(None, {"task": user_module, "arms": ["hybrid"], "seeds": [0], "preset": "smoke"},
                                 tasks=command_tasks([user_module]))
    job = cfg.jobs()[0]
    assert dict(job.shaping.label_potentials) == {"VALLEY": 0.0, "HILL": 1.0}  # the task's map, not MountainCar's
    assert job.identity()["task"] == user_module and job.ppo.timesteps == 1_024


@pytest.mark.slow
def test_a_user_task_runs_a_smoke_sweep(tmp_path: Path, user_module: str) -> None:
    uri = f"sqlite:///{tmp_path / 'm.db'}"
    cfg = RunConfig.from_sources(None, {"task": user_module, "arms": ["baseline", "hybrid"], "seeds": [0],
                                        "preset": "smoke", "workers": 1, "tracking_uri": uri},
                                 tasks=command_tasks([user_module]))
    summary = run_sweep(cfg, SilentReporter())
    assert len(summary.finished) == 2 and not summary.failed
    client = store.connect(uri)
    exp = client.get_experiment_by_name(cfg.experiment)
    assert exp is not None
    runs = [r for r in client.search_runs([exp.experiment_id]) if r.data.tags.get("vlmrl.kind") == "train"]
    assert {r.data.tags["vlmrl.task"] for r in runs} == {user_module}
    hybrid = next(r for r in runs if r.data.tags["vlmrl.arm"] == "hybrid")
    assert hybrid.data.metrics["vlm/queries"] > 0 and hybrid.data.metrics["vlm/parse_failures"] == 0
    assert "pixel-reader-v1-valley/" in hybrid.data.tags["vlmrl.vlm"]


def test_the_grid_world_example_reads_every_frame_of_random_episodes_as_the_truth(room_module: str) -> None:
    task = import_task(room_module)
    camera = task.camera.make(ShapingConfig())
    assert isinstance(camera, CellCamera)
    env = task.make_env()
    rng = np.random.default_rng(0)
    frames, seen = 0, set()
    for episode in range(6):
        env.reset(seed=episode)
        done = False
        while True:
            sim = env.unwrapped
            assert task.reader.read(camera.look(sim).frame().pixels) == task.truth(sim)
            frames += 1
            seen.add(task.truth(sim))
            if done:
                break
            _, _, terminated, truncated, _ = env.step(int(rng.integers(3)))  # left, right, forward
            done = terminated or truncated
    assert frames > 300 and seen == {"FAR", "NEAR", "AT_GOAL"}
    assert camera.cells <= 4 * 4 * 4  # 16 floor cells x 4 directions, each drawn once
    assert task.reader.read(np.zeros((120, 120, 3), dtype=np.uint8)) is None


@pytest.mark.slow
def test_the_grid_world_example_runs_study_and_evaluate_end_to_end(tmp_path: Path, room_module: str) -> None:
    uri = f"sqlite:///{tmp_path / 'room.db'}"
    out = tmp_path / "study"
    result = runner.invoke(app, [
        "study", "--task", room_module, "--regime", "smoke", "--arms", "baseline,kinematic,hybrid,hybrid-shuffled",
        "--seeds", "1", "--workers", "1", "--alphas", "none", "--kin-scales", "none", "--query-flickers", "none",
        "--profiles", "none", "--flickers", "none", "--tracking-uri", uri, "--out", str(out),
        "--set", f"vlm.cache_path={tmp_path / 'c.sqlite'}"])
    assert result.exit_code == 0, result.output + result.stderr
    per_seed = pd.read_csv(out / "per_seed.csv")
    assert sorted(per_seed["arm"]) == ["baseline", "hybrid", "hybrid-shuffled", "kinematic"]
    report = (out / "report.md").read_text()
    assert "SIMULATED VLM" in report and "seeds reaching 0.9" in report
    client = store.connect(uri)
    exp = client.get_experiment_by_name("vlmrl-study")
    assert exp is not None
    runs = [r for r in client.search_runs([exp.experiment_id]) if r.data.tags.get("vlmrl.kind") == "train"]
    assert {r.data.tags["vlmrl.task"] for r in runs} == {room_module}
    hybrid = next(r for r in runs if r.data.tags["vlmrl.arm"] == "hybrid")
    assert hybrid.data.metrics["vlm/queries"] > 0 and hybrid.data.metrics["vlm/parse_failures"] == 0
    kinematic = next(r for r in runs if r.data.tags["vlmrl.arm"] == "kinematic")
    assert "vlm/queries" not in kinematic.data.metrics  # the dense term alone asks the VLM nothing

    args = ["evaluate", hybrid.info.run_id, "--episodes", "1", "--tracking-uri", uri, "--out", str(tmp_path / "ev"),
            "--cache-path", str(tmp_path / "c.sqlite")]
    refused = runner.invoke(app, args)  # the store names a module: imported only when the command line does
    assert refused.exit_code == 2 and "names a Python module" in refused.stderr, refused.output + refused.stderr
    evaluated = runner.invoke(app, [*args, "--user-task", room_module])
    assert evaluated.exit_code == 0, evaluated.output + evaluated.stderr
    assert (tmp_path / "ev" / "episode-0.gif").is_file() and evaluated.stdout.startswith("WARNING: SIMULATED VLM")
