"""Finding tasks: built-in names, a user's ``package.module:NAME`` (the docs' example, run as a
smoke sweep), and every way a name can be wrong."""

from __future__ import annotations

import re
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.sweep.runner import SilentReporter, run_sweep
from vlmrl_cli.tasks.base import Task
from vlmrl_cli.tasks.registry import BUILTIN, DEFAULT_TASK, get_task, task_names
from vlmrl_cli.tracking import store
from vlmrl_cli.training.config import RunConfig

DOCS = Path(__file__).resolve().parents[2] / "docs" / "tasks.md"


def _example_code() -> str:
    """The one ``python`` block of docs/tasks.md: the "Add a task" example, verbatim."""
    blocks = re.findall(r"```python\n(.*?)```", DOCS.read_text(encoding="utf-8"), flags=re.S)
    assert len(blocks) == 1, "docs/tasks.md should hold exactly one python example"
    return blocks[0]


@pytest.fixture
def user_module(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """The docs' example as ``mytasks_valley`` on sys.path and on the workers' PYTHONPATH."""
    (tmp_path / "mytasks_valley.py").write_text(_example_code(), encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", f"{tmp_path}:{':'.join(p for p in sys.path if p)}")
    yield "mytasks_valley:TASK"
    sys.modules.pop("mytasks_valley", None)


def test_every_builtin_task_loads_and_mountain_car_is_the_default() -> None:
    assert DEFAULT_TASK == "mountain-car" and task_names()[:len(BUILTIN)] == list(BUILTIN)
    for name in BUILTIN:
        task = get_task(name)
        assert isinstance(task, Task) and task.name == name
        assert task.labels_problem(task.label_potentials) is None
        assert task.make_env().spec is not None


@pytest.mark.parametrize(("name", "words"), [
    ("acrobat", "did you mean 'acrobot'"),
    ("no_such_module_xyz:TASK", "cannot import no_such_module_xyz"),
    ("math:pi", "is a float, not a vlmrl_cli.tasks.base.Task"),
    ("math:nothing_here", "math has no nothing_here"),
    (":TASK", "give package.module:NAME"),
])
def test_a_bad_task_name_says_why(name: str, words: str) -> None:
    with pytest.raises(BadInput, match=re.escape(words)):
        get_task(name)


def test_the_docs_example_task_loads_from_a_user_module(user_module: str) -> None:
    task = get_task(user_module)
    assert task.name == "valley" and task.milestones.labels == ("VALLEY", "HILL")
    cfg = RunConfig.from_sources(None, {"task": user_module, "arms": ["hybrid"], "seeds": [0], "preset": "smoke"})
    job = cfg.jobs()[0]
    assert dict(job.shaping.label_potentials) == {"VALLEY": 0.0, "HILL": 1.0}  # the task's map, not MountainCar's
    assert job.identity()["task"] == user_module and job.ppo.timesteps == 1_024


@pytest.mark.slow
def test_a_user_task_runs_a_smoke_sweep(tmp_path: Path, user_module: str) -> None:
    uri = f"sqlite:///{tmp_path / 'm.db'}"
    cfg = RunConfig.from_sources(None, {"task": user_module, "arms": ["baseline", "hybrid"], "seeds": [0],
                                        "preset": "smoke", "workers": 1, "tracking_uri": uri})
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
