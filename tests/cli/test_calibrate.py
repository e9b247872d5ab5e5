"""`vlmrl calibrate` end to end on a two-regime smoke grid, two seeds, in a temporary sqlite store."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
from mlflow.tracking import MlflowClient
from typer.testing import CliRunner

from vlmrl_cli.cli.app import app

pytestmark = pytest.mark.slow  # trains, starts Ray or servers, or builds the wheel

runner = CliRunner()


def _uri(root: Path) -> str:
    return f"sqlite:///{root / 'store' / 'mlflow.db'}"


def _calibrate(root: Path, *args: str):  # type: ignore[no-untyped-def]
    return runner.invoke(
        app,
        [
            "calibrate",
            "--preset",
            "smoke",
            "--seeds",
            "2",
            "--workers",
            "2",
            "--set",
            "ppo.timesteps=512",
            "--set",
            "ppo.eval_episodes=1",
            "--tracking-uri",
            _uri(root),
            "--out",
            str(root / "out"),
            *args,
        ],
    )


def _runs(root: Path) -> list:  # type: ignore[type-arg]
    client = MlflowClient(tracking_uri=_uri(root))
    exp = client.get_experiment_by_name("vlmrl-calibrate")
    return [] if exp is None else list(client.search_runs([exp.experiment_id], max_results=1000))


def test_a_smoke_grid_writes_every_output_once_and_a_rerun_trains_nothing(tmp_path: Path) -> None:
    toml = tmp_path / "cal.toml"
    toml.write_text('[calibrate.grid]\n"ppo.normalize_obs" = [true, false]\n')
    result = _calibrate(tmp_path, "--config", str(toml))
    assert result.exit_code == 0, result.output + result.stderr
    out = tmp_path / "out"
    assert {p.name for p in out.iterdir()} == {"calibration.md", "calibration.csv", "calibration.png", "manifest.json"}
    table = pd.read_csv(out / "calibration.csv")
    assert sorted(table["regime"]) == ["ppo.normalize_obs=false", "ppo.normalize_obs=true"]
    assert (table["seeds"] == 2).all() and (table["budget"] == 512).all()
    assert table["distance"].is_monotonic_increasing and (table["distance"] > 0).all()
    assert {"ppo.normalize_obs", "reliability_low", "steps_-130_high", "distance_low"} <= set(table.columns)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["git_commit"] and manifest["runs_trained_now"] == 4 and manifest["command"].startswith("vlmrl")
    assert "the runs' own wall times sum to" in (out / "calibration.md").read_text()

    runs = _runs(tmp_path)
    train = [r for r in runs if r.data.tags["vlmrl.kind"] == "train"]
    assert len(train) == 4 and {r.data.tags["vlmrl.regime"] for r in train} == {
        "ppo.normalize_obs=true",
        "ppo.normalize_obs=false",
    }
    (cal,) = [r for r in runs if r.data.tags["vlmrl.kind"] == "calibration"]
    names = {a.path for a in MlflowClient(tracking_uri=_uri(tmp_path)).list_artifacts(cal.info.run_id)}
    assert {"calibration.md", "calibration.csv", "calibration.png", "manifest.json"} <= names

    again = _calibrate(tmp_path, "--grid", "ppo.normalize_obs=true,false")
    assert again.exit_code == 0, again.output + again.stderr
    assert "0 run(s) trained" in again.output
    assert {r.info.run_id for r in _runs(tmp_path)} == {r.info.run_id for r in runs}  # nothing new, same run


@pytest.mark.parametrize(
    ("args", "toml", "needle"),
    [
        (["--grid", "ppo.nenvs=1,2"], "", "did you mean 'ppo.n_envs'"),
        (["--grid", "ppo.gamma=0.9,1.5"], "", "ppo.gamma"),
        (["--grid", "ppo.n_envs="], "", "lists no value"),
        (["--grid", "ppo.n_envs=1,2", "--grid", "ppo.n_envs=4"], "", "--grid ppo.n_envs is given twice"),
        (["--set", "shaping.alpha=-1"], "", "shaping.alpha"),
        ([], "[calibrate]\ngird = {}\n", "did you mean 'grid'"),
        ([], '[calibrate.grid]\n"shaping.alpha" = 3\n', "calibrate.grid.shaping.alpha"),
        ([], '[calibrate.grid]\n"ppo.n_steps" = [16, 1]\n', "ppo.batch_size"),
        (["--set", "ppo.nenvs=1"], "", "did you mean 'ppo.n_envs'"),
        (["--set", "n_envs"], "", "KEY=VALUE"),
        (["--set", "vlm.backend=gpt9"], "", "unknown VLM backend 'gpt9'"),
        (["--preset", "nope"], "", "unknown preset 'nope'"),
        (["--seed-list", "a,b"], "", "--seed-list"),
        (["--config", "{tmp}/missing.toml"], "", "cannot read the config file"),
        (["--out", "{tmp}/file/out"], "", "output folder"),  # checked before training, not after
        (["--tracking-uri", "sqlite:///{tmp}/file/mlflow.db"], "", "cannot be reached"),
        (["--tracking-uri", "nope://x"], "", "cannot be reached"),
    ],
)
def test_a_bad_input_exits_2_before_anything_exists(tmp_path: Path, args: list[str], toml: str, needle: str) -> None:
    (tmp_path / "file").write_text("not a folder")
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    if toml:
        (tmp_path / "cal.toml").write_text(toml)
        args = [*args, "--config", str(tmp_path / "cal.toml")]
    result = _calibrate(tmp_path, *args)
    assert result.exit_code == 2, result.output + result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and needle in lines[0], lines
    assert not (tmp_path / "store").exists() and not (tmp_path / "out").exists()
    assert {p.name for p in tmp_path.iterdir()} <= {"file", "cal.toml"}  # no store, folder or output anywhere
