"""`vlmrl run` end to end on the `smoke` preset, in a temporary sqlite MLflow store."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest
from mlflow.tracking import MlflowClient
from typer.testing import CliRunner

from vlmrl_cli.cli.app import app

pytestmark = pytest.mark.slow  # trains, starts Ray or servers, or builds the wheel

runner = CliRunner()


def _uri(root: Path) -> str:
    return f"sqlite:///{root / 'mlflow.db'}"


def _run(root: Path, *args: str):  # type: ignore[no-untyped-def]
    return runner.invoke(app, ["run", "--preset", "smoke", "--tracking-uri", _uri(root),
                               "--cache-path", str(root / "cache.sqlite"), *args])


def _runs(root: Path, experiment: str = "vlmrl") -> list:  # type: ignore[type-arg]
    client = MlflowClient(tracking_uri=_uri(root))
    exp = client.get_experiment_by_name(experiment)
    return [] if exp is None else list(client.search_runs([exp.experiment_id], max_results=1000))


def _children(runs: list) -> list:  # type: ignore[type-arg]
    return [r for r in runs if r.data.tags.get("vlmrl.kind") == "train"]


@pytest.fixture(scope="module")
def swept_with_output(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """One sweep that the tests of this file read (none changes its experiment): its root, its output."""
    root = tmp_path_factory.mktemp("sweep")
    result = _run(root, "--arms", "baseline,hybrid", "--seeds", "2")
    assert result.exit_code == 0, result.output + result.stderr
    return root, result.output


@pytest.fixture(scope="module")
def swept(swept_with_output: tuple[Path, str]) -> Path:
    return swept_with_output[0]


def test_one_parent_and_four_finished_children_with_provenance(swept: Path) -> None:
    runs = _runs(swept)
    parents = [r for r in runs if r.data.tags.get("vlmrl.kind") == "sweep"]
    children = _children(runs)
    assert len(parents) == 1 and len(children) == 4
    assert {(r.data.tags["vlmrl.arm"], r.data.tags["vlmrl.seed"]) for r in children} == {
        ("baseline", "0"), ("baseline", "1"), ("hybrid", "0"), ("hybrid", "1")}
    client = MlflowClient(tracking_uri=_uri(swept))
    for run in children:
        tags, params, metrics = run.data.tags, run.data.params, run.data.metrics
        assert run.info.status == "FINISHED"
        assert tags["mlflow.parentRunId"] == parents[0].info.run_id
        assert len(tags["vlmrl.config_hash"]) == 12
        assert tags["vlmrl.git_commit"] and tags["vlmrl.version.stable-baselines3"]
        assert params["timesteps"] == "1024" and params["arm.name"] == tags["vlmrl.arm"]
        for key in ("eval/success_rate", "eval/mean_length", "eval/mean_return", "perf/steps_per_s"):
            assert key in metrics, key
        history = client.get_metric_history(run.info.run_id, "episode/native_return")
        assert history and all(m.step <= 1024 for m in history)
        assert len(client.get_metric_history(run.info.run_id, "eval/episode_length")) == 5  # smoke: 5 episodes
        names = {a.path for a in client.list_artifacts(run.info.run_id)}
        assert {"model.zip", "vecnormalize.npz", "config.json"} <= names and "vecnormalize.pkl" not in names
        if tags["vlmrl.arm"] == "hybrid":
            assert "SIMULATED" in tags["vlmrl.vlm"] and tags["vlmrl.simulated"] == "true"
            assert metrics["vlm/queries"] > 0 and metrics["vlm/prototypes"] > 0
            # the VLM's cost: one call per labelling round with a miss, the frames they carried
            assert 0 < metrics["vlm/backend_calls"] <= metrics["vlm/backend_frames"] <= metrics["vlm/queries"]
            assert 1 <= metrics["vlm/largest_batch"] <= 16 and 0.0 <= metrics["vlm/wait_share"] < 1.0
            assert metrics["vlm/budget_labels"] == 0 and "vlm.max_queries" not in params  # no budget: no param
            assert "transcript.jsonl" in names
            assert "episode/shaped_return" in metrics
        else:
            assert tags["vlmrl.simulated"] == "false"  # the baseline asks no VLM


def test_rerunning_the_same_command_starts_no_new_run(swept: Path) -> None:
    before = {r.info.run_id for r in _runs(swept)}
    result = _run(swept, "--arms", "baseline,hybrid", "--seeds", "2")
    assert result.exit_code == 0, result.output + result.stderr
    assert "already FINISHED" in result.output
    assert {r.info.run_id for r in _runs(swept)} == before


def test_a_run_left_running_is_marked_failed_and_redone(tmp_path: Path) -> None:
    assert _run(tmp_path, "--arms", "baseline", "--seed-list", "3", "--workers", "1").exit_code == 0
    (first,) = _children(_runs(tmp_path))
    client = MlflowClient(tracking_uri=_uri(tmp_path))
    client.update_run(first.info.run_id, status="RUNNING")  # as a crash would leave it
    result = _run(tmp_path, "--arms", "baseline", "--seed-list", "3", "--workers", "1")
    assert result.exit_code == 0, result.output + result.stderr
    children = {r.info.run_id: r for r in _children(_runs(tmp_path))}
    assert children[first.info.run_id].info.status == "FAILED"
    assert len(children) == 2
    assert sorted(r.info.status for r in children.values()) == ["FAILED", "FINISHED"]


def test_same_config_and_seed_give_identical_native_returns(swept: Path) -> None:
    """The sweep's hybrid seed 1 (trained beside three other jobs by a pool of two workers) and the
    same job alone in a fresh one-worker pool give the same curve."""
    result = _run(swept, "--arms", "hybrid", "--seed-list", "1", "--workers", "1", "--experiment", "alone")
    assert result.exit_code == 0, result.output + result.stderr
    client = MlflowClient(tracking_uri=_uri(swept))
    returns = []
    for runs in (_runs(swept), _runs(swept, "alone")):
        (run,) = [r for r in _children(runs) if (r.data.tags["vlmrl.arm"], r.data.tags["vlmrl.seed"]) == (
            "hybrid", "1")]
        history = client.get_metric_history(run.info.run_id, "episode/native_return")
        returns.append([(m.step, m.value) for m in sorted(history, key=lambda m: (m.step, m.timestamp))])
    assert returns[0] and returns[0] == returns[1]


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--arms", "baseline,teleport"], "unknown arm"),
        (["--arms", "baseline", "--preset", "huge"], "unknown preset"),
        (["--arms", "baseline", "--seeds", "0"], "--seeds"),
        (["--arms", "baseline", "--set", "ppo.timesteps=0"], "ppo.timesteps"),
        (["--arms", "hybrid", "--vlm", "nonsense"], "unknown VLM backend"),
        (["--arms", "hybrid", "--vlm", "openai", "--model", "m", "--timeout", "1", "--retries", "0",
          "--base-url", "http://127.0.0.1:{port}/v1"], "unreachable"),
    ],
)
def test_bad_input_exits_2_with_one_sentence_before_training(tmp_path: Path, args: list[str], needle: str) -> None:
    args = [a.replace("{port}", str(_closed_port())) for a in args]
    result = _run(tmp_path, *args)
    assert result.exit_code == 2, result.output + result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and needle in lines[0]
    assert "Traceback" not in result.stderr + result.output
    assert _children(_runs(tmp_path)) == []


def test_malformed_config_file_and_unreachable_tracking_store_exit_2(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("arms = [\n")
    result = _run(tmp_path, "--config", str(bad))
    assert result.exit_code == 2 and "not valid TOML" in result.stderr
    result = runner.invoke(app, ["run", "--arms", "baseline", "--preset", "smoke",
                                 "--tracking-uri", f"http://127.0.0.1:{_closed_port()}"])
    assert result.exit_code == 2 and "cannot be reached" in result.stderr


def test_config_file_sets_knobs_and_flags_override_it(tmp_path: Path) -> None:
    cfg = tmp_path / "run.toml"
    cfg.write_text('arms = ["baseline"]\nseeds = [5]\npreset = "smoke"\ntimesteps = 512\nworkers = 1\n'
                   'experiment = "from-file"\n')
    result = runner.invoke(app, ["run", "--config", str(cfg), "--tracking-uri", _uri(tmp_path),
                                 "--timesteps", "256"])
    assert result.exit_code == 0, result.output + result.stderr
    (run,) = _children(_runs(tmp_path, "from-file"))
    assert run.data.tags["vlmrl.seed"] == "5" and run.data.params["timesteps"] == "256"


def test_the_run_ends_with_its_child_runs_and_the_dry_run_lists_them_again(
        swept_with_output: tuple[Path, str]) -> None:
    root, output = swept_with_output
    ids = {(r.data.tags["vlmrl.arm"], r.data.tags["vlmrl.seed"]): r.info.run_id for r in _children(_runs(root))}
    assert len(ids) == 4 and "training runs (vlmrl evaluate RUN_ID):" in output
    for (arm, seed), run_id in ids.items():
        assert any(line.split()[:3] == [arm, seed, run_id] for line in output.splitlines()), (arm, seed)
    dry = _run(root, "--arms", "baseline,hybrid", "--seeds", "2", "--dry-run")
    assert dry.exit_code == 0 and all(run_id in dry.output for run_id in ids.values()), dry.output


@pytest.mark.parametrize(("args", "needle"), [
    (["--arms", "baseline,,hybrid"], "has an empty entry"),
    (["--seeds", "2", "--seed-list", "3"], "--seeds and --seed-list both given"),
    (["--seed-list", "3,,4"], "has an empty entry"),
    (["--seed-list", "3,3"], "lists a seed twice"),
    (["--seed-list", "a,b"], "must be comma-separated integers"),
    (["--set", "shaping.alpha=-1"], "invalid shaping.alpha = -1"),
    (["--set", "shaping.alpha=nan"], "input should be a finite number"),
    (["--set", "shaping.kin_scale=inf"], "input should be a finite number"),
])
def test_ambiguous_or_non_finite_input_is_refused_before_anything_exists(tmp_path: Path, args: list[str],
                                                                          needle: str) -> None:
    result = _run(tmp_path, *args)
    assert result.exit_code == 2, result.output + result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and needle in lines[0], lines
    assert not any(tmp_path.iterdir())


def test_a_query_budget_is_respected_and_recorded(tmp_path: Path) -> None:
    result = _run(tmp_path, "--arms", "hybrid", "--seeds", "1", "--set", "vlm.max_queries=5")
    assert result.exit_code == 0, result.output + result.stderr
    (run,) = _children(_runs(tmp_path))
    metrics, params = run.data.metrics, run.data.params
    assert params["vlm.max_queries"] == "5" and "vlm.max_queries=5" in run.data.tags["vlmrl.overrides"]
    assert metrics["vlm/queries"] == 5 and metrics["vlm/backend_frames"] <= 5 and metrics["vlm/budget_labels"] > 0


def test_the_dry_run_states_a_real_vlms_queries_and_time(tmp_path: Path) -> None:
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    args = ["run", "--arms", "baseline,hybrid", "--seeds", "2", "--preset", "smoke", "--dry-run", "--tracking-uri", uri]
    slow = CliRunner().invoke(app, [*args, "--vlm-qps", "1"])
    fast = CliRunner().invoke(app, [*args, "--vlm-qps", "10"])
    assert slow.exit_code == 0 and fast.exit_code == 0, slow.output
    line = next(x for x in slow.output.splitlines() if x.startswith("# VLM cost"))
    assert "2 run(s) ask the VLM" in line and "at 1 queries/s" in line and "simulated VLM" in line
    assert "at 10 queries/s" in fast.output
    assert CliRunner().invoke(app, [*args, "--vlm-qps", "0"]).exit_code == 2
