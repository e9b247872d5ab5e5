"""`vlmrl verify` end to end: smoke runs trained by `vlmrl run`, exported, retrained from the
export and from the store, then a tampered export that must be caught; its cost estimate on a
synthetic export."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from vlmrl_cli.cli.app import app
from vlmrl_cli.sweep.cost import FALLBACK_S_PER_STEP, SLOWER_MACHINE
from vlmrl_cli.tracking.transfer import FORMAT, read_records, write_records
from vlmrl_cli.training.config import RunConfig

slow = pytest.mark.slow  # the tests that train

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


@slow
def test_every_run_of_an_export_retrains_identically(exported: tuple[str, Path]) -> None:
    result = runner.invoke(app, ["verify", str(exported[1]), "--workers", "2"])
    assert result.exit_code == 0, result.output + result.stderr
    assert result.output.count("identical (") == 4 and "4 identical, 0 differ" in result.output
    assert "here: pin x86-64-v3/1" in result.output
    assert result.output.count("    recorded: pin x86-64-v3/1") == 4  # the recorded side of each run, identical or not


@slow
def test_a_sample_of_a_store_by_seed(exported: tuple[str, Path]) -> None:
    result = runner.invoke(app, ["verify", "--experiment", "src", "--tracking-uri", exported[0], "--seed", "1",
                                 "--sample", "1"])
    assert result.exit_code == 0, result.output + result.stderr
    assert "verifying 1 of 4 run(s)" in result.output and "-s1: identical" in result.output


@slow
def test_a_dry_run_lists_the_runs_and_the_cost_and_trains_nothing(exported: tuple[str, Path]) -> None:
    result = runner.invoke(app, ["verify", str(exported[1]), "--arm", "hybrid", "--dry-run"])
    assert result.exit_code == 0, result.output
    assert "verifying 2 of 4 run(s)" in result.output and "about" in result.output
    assert "identical" not in result.output


@slow
def test_a_tampered_return_is_caught_at_its_episode(exported: tuple[str, Path], tmp_path: Path) -> None:
    records = list(read_records(exported[1]))
    target = next(r for r in records if r["run_name"] == "baseline-s0")
    target["histories"]["episode/native_return"]["value"][3] += 1.0
    tampered = tmp_path / "tampered.jsonl.gz"
    write_records(tampered, records)  # with a digest of its own: whoever edits a file can write one
    result = runner.invoke(app, ["verify", str(tampered), "--run-id", target["source_run_id"][:10]])
    assert result.exit_code == 1
    assert "differs from episode 3" in result.output and "recorded:" in result.output
    assert "did not reproduce" in result.stderr


@slow
def test_a_config_this_code_would_hash_differently_is_refused_before_training(exported: tuple[str, Path],
                                                                               tmp_path: Path) -> None:
    records = list(read_records(exported[1]))
    config = json.loads(records[0]["artifacts"]["config.json"])
    config["ppo"]["learning_rate"] = 0.5
    records[0]["artifacts"]["config.json"] = json.dumps(config)
    bad = tmp_path / "bad.jsonl.gz"
    write_records(bad, records[:1])
    result = runner.invoke(app, ["verify", str(bad)])
    assert result.exit_code == 2 and "would train another experiment" in result.stderr


def _synthetic_export(path: Path, walls: list[float | None]) -> Path:
    """An export of smoke baseline runs (seeds 0, 1, ...) whose configs rebuild here, one per wall time
    recorded (None: the run recorded none); nothing in it was trained."""
    jobs = RunConfig.from_sources(None, {"arms": ["baseline"], "seeds": list(range(len(walls))),
                                         "preset": "smoke"}).jobs()
    records = []
    for job, wall in zip(jobs, walls, strict=True):
        records.append({"format": FORMAT, "source_run_id": f"{job.seed:08d}deadbeef", "run_name": job.name,
                        "start_time": 0, "end_time": 1, "params": {},
                        "tags": {"vlmrl.kind": "train", "vlmrl.arm": job.arm.name, "vlmrl.seed": str(job.seed),
                                 "vlmrl.config_hash": job.config_hash},
                        "latest": {} if wall is None else {"perf/wall_s": [0, 1, wall]},
                        "histories": {"episode/native_return": {"step": [200], "ts": [1], "value": [-200.0]}},
                        "artifacts": {"config.json": json.dumps({"config_hash": job.config_hash, **job.params()})},
                        "binary": {}})
    write_records(path, records)
    return path


def test_the_cost_estimate_rests_on_the_runs_steps_and_per_step_costs(tmp_path: Path) -> None:
    path = _synthetic_export(tmp_path / "runs.jsonl.gz", [60.0, None])
    result = runner.invoke(app, ["verify", str(path), "--dry-run", "--workers", "1"])
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.split())
    minutes = (60.0 + 1_024 * FALLBACK_S_PER_STEP) / 60  # the recorded run, then 1,024 steps at the task's figure
    slower = minutes * SLOWER_MACHINE  # the same runs on a machine 3x slower than the one that recorded them
    assert (f"verifying 2 of 2 run(s) of {path}: about {minutes:,.1f}-{slower:,.1f} min ({minutes:,.1f} at the "
            f"recorded speed, {slower:,.1f} on a machine {SLOWER_MACHINE:g}x slower) on 1 worker(s)") in text
    assert "2,048 steps in all: 1 run(s) at the wall time per step they recorded" in text
    assert f"1 run(s), which recorded no wall time, at their task's mountain-car {FALLBACK_S_PER_STEP * 1e3:.2f} ms" \
        in text
    assert result.output.count("1 episodes, 1,024 steps") == 2 and "identical" not in result.output


@slow
def test_in_a_log_progress_is_a_plain_line_per_finished_run_on_stderr(tmp_path: Path) -> None:
    path = _synthetic_export(tmp_path / "runs.jsonl.gz", [60.0])  # its one recorded return is made up: differs
    result = runner.invoke(app, ["verify", str(path)])  # CliRunner's stderr is no terminal
    assert result.exit_code == 1, result.output
    assert "progress: retraining 1 run(s), 1,024 steps" in result.stderr
    assert "progress: 1/1 run(s), 1,024/1,024 steps" in result.stderr and "min left" in result.stderr
    assert "progress:" not in result.stdout  # the verdicts stay on stdout, alone
