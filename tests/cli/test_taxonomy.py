"""`vlmrl taxonomy` through typer's CliRunner: outputs, one MLflow run, exit code 2 on bad input."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from vlmrl_cli.cli.app import app

runner = CliRunner()  # click 8.2+: result.stderr is kept apart from result.stdout


@pytest.fixture(scope="module")
def shared_uri(tmp_path_factory: pytest.TempPathFactory) -> str:
    """One MLflow database for the error cases (creating one costs seconds)."""
    return f"sqlite:///{tmp_path_factory.mktemp('mlflow')}/mlflow.db"


def _invoke(*args: str):
    return runner.invoke(app, ["taxonomy", *args])


def test_sim_writes_tables_figure_and_one_simulated_run(tmp_path: Path) -> None:
    from mlflow.tracking import MlflowClient

    d = tmp_path / "D"
    uri = f"sqlite:///{d}/mlflow.db"
    result = _invoke("--vlm", "sim", "--states", "5", "--out", str(d), "--tracking-uri", uri,
                     "--cache-path", str(tmp_path / "cache.sqlite"))
    assert result.exit_code == 0, result.output
    for name in ("table1.md", "table1.csv", "table1.tex", "figure1.png"):
        assert (d / name).is_file()
    assert "SIMULATED VLM" in result.stderr
    assert "cache: 0 hits, 21 misses" in result.stdout
    client = MlflowClient(tracking_uri=uri)
    runs = client.search_runs([e.experiment_id for e in client.search_experiments()])
    assert len(runs) == 1
    assert runs[0].data.tags["vlmrl.simulated"] == "true"
    assert runs[0].info.run_id in result.stdout
    # every output says SIMULATED: captions in the documents, a vlm column in the data files
    for name in ("table1.md", "table1.tex"):
        assert "SIMULATED VLM" in (d / name).read_text(), name
    import pandas as pd

    for name in ("table1.csv", "table1_sweep.csv", "probes.csv"):
        assert pd.read_csv(d / name)["vlm"].str.contains("SIMULATED VLM").all(), name


def test_replay_reproduces_the_paper_rows(tmp_path: Path, shared_uri: str) -> None:
    d = tmp_path / "D"
    result = _invoke("--vlm", "replay", "--out", str(d), "--tracking-uri", shared_uri, "--experiment", "replay",
                     "--cache-path", str(tmp_path / "cache.sqlite"))
    assert result.exit_code == 0, result.output
    md = (d / "table1.md").read_text()
    paper = ("0.378", "0.386", "Error [0, 0, 0, 0]", "Box [450, 210, 480, 230]", "BOTTOM", "ΔΦ = 0.0 (dead zone")
    for snippet in paper:
        assert snippet in md
    assert "paper's reported raw outputs" in md and "SIMULATED" not in md
    assert "n/a" in result.stdout


def _assert_clean_failure(result, out: Path) -> None:
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert "Traceback" not in result.output
    assert not (out / "table1.md").exists()
    assert not list(out.parent.glob(f".{out.name}.partial-*"))


def test_unknown_backend_exits_2(tmp_path: Path, shared_uri: str) -> None:
    out = tmp_path / "D"
    result = _invoke("--vlm", "nonsense", "--out", str(out), "--tracking-uri", shared_uri,
                     "--cache-path", str(tmp_path / "c.sqlite"))
    _assert_clean_failure(result, out)
    assert "nonsense" in result.stderr


@pytest.mark.parametrize("transcript", ["/nonexistent.jsonl", "garbage"])
def test_unreadable_transcript_exits_2(tmp_path: Path, shared_uri: str, transcript: str) -> None:
    if transcript == "garbage":
        path = tmp_path / "garbage.jsonl"
        path.write_bytes(b"\x00\xff not json at all\n{]\n")
        transcript = str(path)
    out = tmp_path / "D"
    result = _invoke("--vlm", "replay", "--transcript", transcript, "--out", str(out), "--tracking-uri", shared_uri,
                     "--cache-path", str(tmp_path / "c.sqlite"))
    _assert_clean_failure(result, out)


def test_unwritable_out_exits_2(tmp_path: Path, shared_uri: str) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    out = blocker / "D"
    result = _invoke("--vlm", "sim", "--states", "2", "--out", str(out), "--tracking-uri", shared_uri,
                     "--cache-path", str(tmp_path / "c.sqlite"))
    assert result.exit_code == 2, result.output
    assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.output


def test_states_below_two_is_a_usage_error(tmp_path: Path) -> None:
    result = _invoke("--states", "1", "--out", str(tmp_path / "D"))
    assert result.exit_code == 2


def test_help_states_the_default_sweep() -> None:
    from vlmrl_cli.probe.scoring import DEFAULT_STATES

    result = _invoke("--help")
    assert result.exit_code == 0
    assert f"default {DEFAULT_STATES}" in " ".join(result.output.split())
