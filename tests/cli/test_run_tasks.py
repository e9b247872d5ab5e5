"""`vlmrl run --task` on the two tasks beyond MountainCar, and `vlmrl evaluate` of their runs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mlflow.tracking import MlflowClient
from typer.testing import CliRunner

from vlmrl_cli.cli.app import app
from vlmrl_cli.tasks.registry import get_task

pytestmark = pytest.mark.slow  # trains

runner = CliRunner()
ARMS = ["baseline", "kinematic", "semantic", "hybrid"]


@pytest.mark.parametrize("task", ["acrobot", "mountain-car-continuous"])
def test_four_arms_finish_tagged_with_their_task_and_evaluate_draws_the_tasks_captions(tmp_path: Path,
                                                                                      task: str) -> None:
    uri = f"sqlite:///{tmp_path / 'm.db'}"
    # one evaluation episode per run: MountainCarContinuous's last up to 999 rendered steps
    result = runner.invoke(app, ["run", "--task", task, "--arms", ",".join(ARMS), "--seeds", "1", "--preset", "smoke",
                                 "--set", "ppo.eval_episodes=1", "--workers", "1", "--tracking-uri", uri,
                                 "--cache-path", str(tmp_path / "c.sqlite")])
    assert result.exit_code == 0, result.output
    top = get_task(task).thresholds[-1]
    assert f"task {task}" in result.output and f"steps to {top:g}" in result.output
    client = MlflowClient(tracking_uri=uri)
    exp = client.get_experiment_by_name("vlmrl")
    assert exp is not None
    runs = client.search_runs([exp.experiment_id])
    train = [r for r in runs if r.data.tags["vlmrl.kind"] == "train"]
    assert sorted(r.data.tags["vlmrl.arm"] for r in train) == sorted(ARMS)
    assert {(r.info.status, r.data.tags["vlmrl.task"]) for r in runs} == {("FINISHED", task)}
    hybrid = next(r for r in train if r.data.tags["vlmrl.arm"] == "hybrid")
    assert "SIMULATED" in hybrid.data.tags["vlmrl.vlm"] and f"pixel-reader-v1-{task}/" in hybrid.data.tags["vlmrl.vlm"]
    assert hybrid.data.metrics["vlm/queries"] > 0 and hybrid.data.metrics["vlm/parse_failures"] == 0

    out = tmp_path / "eval"
    shown = runner.invoke(app, ["evaluate", hybrid.info.run_id, "--tracking-uri", uri, "--out", str(out),
                                "--episodes", "1", "--no-cache"])
    assert shown.exit_code == 0, shown.output
    figures = json.loads((out / "evaluation.json").read_text())
    assert figures["task"] == task and figures["simulated"] is True and (out / "episode-0.gif").stat().st_size > 0
    labels = {f["vlm_answer"] for f in figures["frames"]}
    assert labels and labels <= set(get_task(task).milestones.labels)  # the task's own vocabulary, all parsed
    assert all(len(f["obs"]) == get_task(task).scene.obs_shape[0] for f in figures["frames"])

    report = runner.invoke(app, ["report", "--tracking-uri", uri, "--out", str(tmp_path / "report")])
    assert report.exit_code == 0, report.output
    text = (tmp_path / "report" / "report.md").read_text()
    assert text.startswith(f"# Report (task {task})") and "## Claims" not in text  # no paper claims off MountainCar
    assert f"Steps to reach {top:g}" in text and "SIMULATED VLM" in text
