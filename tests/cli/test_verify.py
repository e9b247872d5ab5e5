"""`vlmrl verify` end to end: smoke runs trained by `vlmrl run`, exported, retrained from the
export and from the store, then a tampered export that must be caught."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from vlmrl_cli.cli.app import app

pytestmark = pytest.mark.slow  # trains

runner = CliRunner()


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, Path]:
    root = tmp_path_factory.mktemp("verify")
    uri = f"sqlite:///{root / 'm.db'}"
    result = runner.invoke(app, ["run", "--arms", "baseline,hybrid", "--seeds", "2", "--preset", "smoke",
                                 "--workers", "1", "--set", "ppo.eval_episodes=1", "--timesteps", "2048",
                                 "--set", f"vlm.cache_path={root / 'c.sqlite'}", "--tracking-uri", uri,
                                 "--experiment", "src"])
    assert result.exit_code == 0, result.output + result.stderr
    path = root / "runs.jsonl.gz"
    result = runner.invoke(app, ["export", "--experiment", "src", "--tracking-uri", uri, "--out", str(path)])
    assert result.exit_code == 0, result.output
    return uri, path


def test_every_run_of_an_export_retrains_identically(exported: tuple[str, Path]) -> None:
    result = runner.invoke(app, ["verify", str(exported[1]), "--workers", "2"])
    assert result.exit_code == 0, result.output + result.stderr
    assert result.output.count("identical (") == 4 and "4 identical, 0 differ" in result.output
    assert "here: pin x86-64-v3/1" in result.output
    assert result.output.count("    recorded: pin x86-64-v3/1") == 4  # the recorded side of each run, identical or not


def test_a_sample_of_a_store_by_seed(exported: tuple[str, Path]) -> None:
    result = runner.invoke(app, ["verify", "--experiment", "src", "--tracking-uri", exported[0], "--seed", "1",
                                 "--sample", "1"])
    assert result.exit_code == 0, result.output + result.stderr
    assert "verifying 1 of 4 run(s)" in result.output and "-s1: identical" in result.output


def test_a_dry_run_lists_the_runs_and_the_cost_and_trains_nothing(exported: tuple[str, Path]) -> None:
    result = runner.invoke(app, ["verify", str(exported[1]), "--arm", "hybrid", "--dry-run"])
    assert result.exit_code == 0, result.output
    assert "verifying 2 of 4 run(s)" in result.output and "about" in result.output
    assert "identical" not in result.output


def test_a_tampered_return_is_caught_at_its_episode(exported: tuple[str, Path], tmp_path: Path) -> None:
    with gzip.open(exported[1], "rt", encoding="utf-8") as lines:
        records = [json.loads(line) for line in lines]
    target = next(r for r in records if r["run_name"] == "baseline-s0")
    target["histories"]["episode/native_return"]["value"][3] += 1.0
    tampered = tmp_path / "tampered.jsonl.gz"
    with gzip.open(tampered, "wt", encoding="utf-8") as out:
        out.write("".join(json.dumps(r) + "\n" for r in records))
    result = runner.invoke(app, ["verify", str(tampered), "--run-id", target["source_run_id"][:10]])
    assert result.exit_code == 1
    assert "differs from episode 3" in result.output and "recorded:" in result.output
    assert "did not reproduce" in result.stderr


def test_a_config_this_code_would_hash_differently_is_refused_before_training(exported: tuple[str, Path],
                                                                               tmp_path: Path) -> None:
    with gzip.open(exported[1], "rt", encoding="utf-8") as lines:
        records = [json.loads(line) for line in lines]
    config = json.loads(records[0]["artifacts"]["config.json"])
    config["ppo"]["learning_rate"] = 0.5
    records[0]["artifacts"]["config.json"] = json.dumps(config)
    bad = tmp_path / "bad.jsonl.gz"
    with gzip.open(bad, "wt", encoding="utf-8") as out:
        out.write(json.dumps(records[0]) + "\n")
    result = runner.invoke(app, ["verify", str(bad)])
    assert result.exit_code == 2 and "would train another experiment" in result.stderr
