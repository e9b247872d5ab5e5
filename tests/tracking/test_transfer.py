"""Export a store's finished runs to one file and import them elsewhere: resume and reports find them."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from vlmrl_cli.analysis.load import load_experiment
from vlmrl_cli.cli.app import app
from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.tracking import store
from vlmrl_cli.tracking.transfer import FORMAT, TAG_IMPORTED_FROM, export_runs, import_runs, read_records

pytestmark = pytest.mark.slow  # trains, starts Ray or servers, or builds the wheel

runner = CliRunner()


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> str:
    root = tmp_path_factory.mktemp("source")
    uri = f"sqlite:///{root / 'm.db'}"
    result = runner.invoke(app, ["run", "--arms", "baseline,hybrid-shuffled", "--seeds", "2", "--preset", "smoke",
                                 "--workers", "1", "--set", "ppo.eval_episodes=2",
                                 "--set", f"vlm.cache_path={root / 'c.sqlite'}", "--tracking-uri", uri,
                                 "--experiment", "src"])
    assert result.exit_code == 0, result.output + result.stderr
    return uri


def test_a_round_trip_keeps_what_the_analysis_reads(source: str, tmp_path: Path) -> None:
    path = tmp_path / "runs.jsonl.gz"
    assert export_runs(store.connect(source), "src", path).written == 4
    records = list(read_records(path))
    assert {r["format"] for r in records} == {FORMAT} and all("config.json" in r["artifacts"] for r in records)
    assert not any(r["binary"] for r in records)  # models only on request

    target = store.connect(f"sqlite:///{tmp_path / 'new' / 'm.db'}")
    assert import_runs(target, path, "dst").written == 4
    before, after = load_experiment(store.connect(source), "src"), load_experiment(target, "dst")
    cols = ["arm", "seed", "config_hash", "budget", "eval_success_rate", "eval_mean_length"]
    pd.testing.assert_frame_equal(before.runs[cols], after.runs[cols])
    drop = ["run_id"]
    pd.testing.assert_frame_equal(before.episodes.drop(columns=drop), after.episodes.drop(columns=drop))
    pd.testing.assert_frame_equal(before.eval_episodes.drop(columns=drop), after.eval_episodes.drop(columns=drop))
    imported = target.search_runs([target.get_experiment_by_name("dst").experiment_id])
    assert all(r.info.status == "FINISHED" and TAG_IMPORTED_FROM in r.data.tags for r in imported)
    assert all("mlflow.parentRunId" not in r.data.tags for r in imported)

    again = import_runs(target, path, "dst")
    assert (again.written, again.skipped) == (0, 4)


def test_a_resumed_sweep_reuses_imported_runs(source: str, tmp_path: Path) -> None:
    path = tmp_path / "runs.jsonl.gz"
    export_runs(store.connect(source), "src", path, models=True)
    uri = f"sqlite:///{tmp_path / 'm.db'}"
    result = runner.invoke(app, ["import", str(path), "--tracking-uri", uri, "--experiment", "dst"])
    assert result.exit_code == 0 and "imported 4 run(s)" in result.output, result.output + result.stderr
    again = runner.invoke(app, ["export", "--out", str(tmp_path / "more.jsonl.gz"), "--tracking-uri", source,
                                "--experiment", "src", "--skip-exported", str(path)])
    assert again.exit_code == 2 and "not in the earlier exports (4 are)" in again.stderr
    dry = runner.invoke(app, ["run", "--arms", "baseline,hybrid-shuffled", "--seeds", "2", "--preset", "smoke",
                              "--set", "ppo.eval_episodes=2", "--tracking-uri", uri, "--experiment", "dst",
                              "--dry-run"])
    assert dry.exit_code == 0 and "4 FINISHED, 0 pending; nothing was trained" in dry.output, dry.output


def test_export_refuses_a_missing_experiment_and_import_a_foreign_file(source: str, tmp_path: Path) -> None:
    with pytest.raises(BadInput, match="does not exist"):
        export_runs(store.connect(source), "nope", tmp_path / "x.gz")
    assert not list(tmp_path.iterdir())
    bad = tmp_path / "bad.jsonl.gz"
    with gzip.open(bad, "wt") as f:
        f.write(json.dumps({"format": "other"}) + "\n")
    result = runner.invoke(app, ["import", str(bad), "--tracking-uri", f"sqlite:///{tmp_path / 's' / 'm.db'}"])
    assert result.exit_code == 2 and "not a vlmrl run export" in result.stderr
    assert not (tmp_path / "s").exists()
