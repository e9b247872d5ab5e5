"""`vlmrl taxonomy --task`: another task's Table 1 (the milestone MCQ row) and Figure 1."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mlflow.tracking import MlflowClient
from typer.testing import CliRunner

from vlmrl_cli.cli.app import app
from vlmrl_cli.probe.milestones import MilestoneProbe, summarize
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.vlm.parsers import ParseStatus

runner = CliRunner()


def test_the_summary_counts_unparsed_answers_wrong_and_gives_a_wilson_interval() -> None:
    probes = [MilestoneProbe(str(i), "LOW", "LOW", "LOW", ParseStatus.OK) for i in range(8)]
    probes += [MilestoneProbe("x", "LOW", "HIGH", "HIGH", ParseStatus.OK),
               MilestoneProbe("y", "HIGH", "", None, ParseStatus.EMPTY)]
    s = summarize(probes, {"LOW": 0.0, "HIGH": 1.0})
    assert (s.frames, s.correct, s.accuracy, s.format_failure_rate) == (10, 8, 0.8, 0.1)
    assert 0.44 < s.accuracy_low < 0.8 < s.accuracy_high < 0.98  # Wilson, 8/10: [0.49, 0.94]
    assert s.mean_abs_dphi == pytest.approx(1 / 9)


@pytest.mark.slow  # renders and probes a few dozen frames
@pytest.mark.parametrize(("task", "states", "frames"), [("acrobot", 9, 9), ("mountain-car-continuous", 13, 13)])
def test_taxonomy_of_a_task_writes_its_labels_table_and_figure(tmp_path: Path, task: str, states: int,
                                                               frames: int) -> None:
    uri = f"sqlite:///{tmp_path / 'm.db'}"
    out = tmp_path / "t"
    result = runner.invoke(app, ["taxonomy", "--task", task, "--vlm", "sim", "--sim-profile", "ideal", "--states",
                                 str(states), "--out", str(out), "--tracking-uri", uri, "--no-cache"])
    assert result.exit_code == 0, result.output
    assert {p.name for p in out.iterdir()} == {"table1.md", "table1.csv", "probes.csv", "figure1.png",
                                               "metrics.json"}
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["task"] == task and metrics["frames"] == frames and metrics["simulated"] is True
    assert metrics["mcq.accuracy"] >= 0.75 and metrics["mcq.format_failure_rate"] == 0.0  # the ideal reader
    text = (out / "table1.md").read_text()
    assert "SIMULATED VLM" in text and all(label in text for label in get_task(task).milestones.labels)
    assert "I float regression | 0 | not defined for this task" in text
    client = MlflowClient(tracking_uri=uri)
    exp = client.get_experiment_by_name("vlmrl-taxonomy")
    assert exp is not None
    (run,) = client.search_runs([exp.experiment_id])
    assert run.info.status == "FINISHED" and run.data.tags["vlmrl.task"] == task


def test_a_bad_output_folder_is_refused_before_anything_exists(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    result = runner.invoke(app, ["taxonomy", "--task", "acrobot", "--out", str(blocker / "t"),
                                 "--tracking-uri", f"sqlite:///{tmp_path / 'm.db'}"])
    assert result.exit_code == 2 and "cannot write to the output folder" in result.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


@pytest.mark.slow  # builds the tiny LLaVA and probes a few frames through it
def test_a_backend_that_scores_is_reported_in_both_modes_on_the_same_frames(tmp_path: Path) -> None:
    from tests.vlm.tiny_llava import build_tiny_llava

    model = build_tiny_llava(tmp_path / "llava", image_gain=30.0)
    uri = f"sqlite:///{tmp_path / 'm.db'}"
    out = tmp_path / "t"
    result = runner.invoke(app, ["taxonomy", "--task", "acrobot", "--vlm", "hf", "--model", str(model), "--device",
                                 "cpu", "--states", "4", "--out", str(out), "--tracking-uri", uri, "--no-cache"])
    assert result.exit_code == 0, result.output
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["mcq.mode"] == "logprob" and metrics["simulated"] is False
    assert metrics["mcq.format_failure_rate"] == 0.0  # a scored answer is always one of the labels
    assert metrics["mcq.generate.format_failure_rate"] == 1.0  # the random model's decoded text is garbage
    assert metrics["mcq.modes_agree"] == 0.0
    client = MlflowClient(tracking_uri=uri)
    exp = client.get_experiment_by_name("vlmrl-taxonomy")
    assert exp is not None
    (run,) = client.search_runs([exp.experiment_id])
    assert "MCQ by option log-probability" in run.data.tags["vlmrl.vlm"]
    assert run.data.metrics["taxonomy.mcq.generate.format_failure_rate"] == 1.0
