"""`vlmrl study` end to end on a smoke grid: 2 regimes x 2 arms x 2 seeds and one VLM variant."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
from mlflow.tracking import MlflowClient
from typer.testing import CliRunner

from vlmrl_cli.cli.app import app

runner = CliRunner()


def _uri(root: Path) -> str:
    return f"sqlite:///{root / 'store' / 'mlflow.db'}"


def _study(root: Path, *args: str):  # type: ignore[no-untyped-def]
    return runner.invoke(app, [
        "study", "--regime", "norm=smoke", "--regime", "raw=preset=smoke ppo.normalize_obs=false "
        "ppo.normalize_reward=false", "--arms", "baseline,hybrid", "--seeds", "2", "--workers", "1",
        "--set", "ppo.timesteps=512", "--set", "ppo.eval_episodes=1", "--set", f"vlm.cache_path={root / 'c.sqlite'}",
        "--profiles", "default,llava-table1", "--flickers", "none", "--states", "4",
        "--alphas", "25", "--kin-scales", "0", "--query-flickers", "none",
        "--tracking-uri", _uri(root), "--out", str(root / "out"), *args,
    ])


@pytest.mark.slow
def test_a_smoke_study_writes_the_map_the_figure_and_the_report(tmp_path: Path) -> None:
    result = _study(tmp_path)
    assert result.exit_code == 0, result.output + result.stderr
    assert "cost estimate: 14 run(s) to train (0 already FINISHED)" in result.output
    out = tmp_path / "out"
    for name in ("regime_map.md", "regime_map.csv", "vlm_quality.csv", "vlm_quality.png", "hacking.csv",
                 "report.md", "manifest.json", "per_seed.csv", "controls.csv", "controls.md"):
        assert (out / name).is_file(), name
    per_seed = pd.read_csv(out / "per_seed.csv")
    assert len(per_seed) == 14 and per_seed["run_id"].is_unique  # every run once
    assert {"regime", "variant", "arm", "seed", "config_hash", "steps_-130", "reached_-130", "auc", "final_return",
            "detached_success", "eval_mean_length"} <= set(per_seed.columns)
    controls = pd.read_csv(out / "controls.csv")
    assert list(controls["control"]) == ["alpha=25 kin=0 vs alpha=0", "alpha=25 kin=0 vs its placebo"]
    assert list(controls["a.arm"]) == ["semantic", "semantic"] and list(controls["b.arm"]) == ["baseline",
                                                                                               "hybrid-shuffled"]
    table = pd.read_csv(out / "regime_map.csv")
    assert list(table["regime"]) == ["norm", "raw"]
    assert {"hybrid.reliability_low", "baseline.steps_high", "hybrid_vs_baseline.speedup", "hybrid_vs_baseline.p",
            "hybrid_vs_baseline.verdict"} <= set(table.columns)
    points = pd.read_csv(out / "vlm_quality.csv")
    assert list(points["variant"]) == ["profile default", "profile llava-table1"]
    assert points["mcq_accuracy"].between(0, 1).all()
    report = (out / "report.md").read_text()
    assert report.index("## Summary") < report.index("## Regime map") < report.index("## Controls") < report.index(
        "## Reward hacking") < report.index("## Method")
    assert "restricted mean" in report and "equivalent within 1.15x" in report and "Power (80%" in report
    assert "SIMULATED VLM" in report and "`norm`" in report and "Hover fraction" in report
    assert "the 14 run(s) this report reads took" in report  # the cost of every run, cells and variants too
    manifest = json.loads((out / "manifest.json").read_text())
    assert [s["stage"] for s in manifest["stages"]] == ["train", "taxonomy", "analysis"]
    assert manifest["git_commit"] and manifest["runs_trained_now"] == 14

    client = MlflowClient(tracking_uri=_uri(tmp_path))
    exp = client.get_experiment_by_name("vlmrl-study")
    assert exp is not None
    runs = client.search_runs([exp.experiment_id], max_results=1000)
    train = [r for r in runs if r.data.tags["vlmrl.kind"] == "train"]
    assert len(train) == 14  # 2 regimes x 2 arms, 1 more profile, semantic and placebo at alpha 25 (x 2 seeds)
    # its five sweeps share one pool: with --workers 1, one worker process trained every run
    assert len({r.data.tags["vlmrl.owner"] for r in train}) == 1
    assert {r.data.tags.get("vlmrl.sim_profile") for r in train if r.data.tags["vlmrl.arm"] == "hybrid"} == {
        "default", "llava-table1"}
    (study,) = [r for r in runs if r.data.tags["vlmrl.kind"] == "study"]
    assert {"report.md", "regime_map.csv", "vlm_quality.png"} <= {a.path for a in client.list_artifacts(
        study.info.run_id)}

    again = _study(tmp_path, "--dry-run")
    assert again.exit_code == 0 and "0 run(s) to train (14 already FINISHED)" in again.output

    # a resumed study keeps the first invocation, which trained the runs, on record
    resumed = _study(tmp_path)
    assert resumed.exit_code == 0, resumed.output + resumed.stderr
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["runs_trained_now"] == 0
    assert [h["runs_trained_now"] for h in manifest["earlier_invocations"]] == [14]
    assert "Earlier invocations of this study" in (out / "report.md").read_text()
    assert "14 run(s) trained" in (out / "report.md").read_text()

    # a progress report of a larger grid: nothing trained, the missing runs named
    partial = _study(tmp_path, "--no-train", "--seeds", "3")
    assert partial.exit_code == 0, partial.output + partial.stderr
    text = (out / "report.md").read_text()
    assert "PARTIAL: 7 of the 21 runs are not FINISHED yet" in text and "0 run(s) trained now" in partial.output


@pytest.mark.parametrize(("args", "needle"), [
    (["--regime", "x=preset=nope"], "unknown preset 'nope'"),
    (["--regime", "nope"], "unknown preset 'nope'"),
    (["--regime", "x=ppo.nenvs=1"], "did you mean 'ppo.n_envs'"),
    (["--profiles", "lava"], "unknown simulated-VLM profile 'lava'"),
    (["--profiles", ","], "--profiles lists no value"),
    (["--profiles", "default,,ideal"], "has an empty entry"),
    (["--arms", "baseline,,hybrid"], "has an empty entry"),
    (["--seeds", "2", "--seed-list", "3"], "--seeds and --seed-list both given"),
    (["--flickers", "abc"], "--flickers takes numbers"),
    (["--flickers", "2"], "vlm.sim.flicker"),
    (["--vlm-regime", "other"], "not a regime of this study"),
    (["--alphas", "-1"], "study.alphas = [-1.0]: must be finite and >= 0"),
    (["--margin", "0.9"], "study.margin = 0.9: must be a ratio above 1"),
    (["--adjust", "bonferroni"], "unknown multiplicity adjustment 'bonferroni'; choose from holm, bh, none"),
    (["--experiment", ""], "an experiment needs a name"),
    (["--kin-scales", "x"], "--kin-scales takes numbers"),
    (["--query-flickers", "2"], "vlm.sim.query_flicker"),
    (["--arms", "teleport"], "unknown arm 'teleport'"),
    (["--set", "ppo.nenvs=1"], "did you mean 'ppo.n_envs'"),
    (["--set", "n_envs"], "KEY=VALUE"),
    (["--config", "{tmp}/missing.toml"], "cannot read the config file"),
    (["--out", "{tmp}/file/out"], "output folder"),
    (["--tracking-uri", "sqlite:///{tmp}/file/mlflow.db"], "cannot be reached"),
    (["--tracking-uri", "nope://x"], "cannot be reached"),
    (["--dry-run", "--arms", "teleport"], "unknown arm 'teleport'"),
    (["--set", "study.margin=0.9"], "study.margin = 0.9: must be a ratio above 1"),  # the [study] table takes --set too
    (["--set", "study.vlm_regime=other"], "not a regime of this study"),
])
def test_a_bad_study_exits_2_before_anything_exists(tmp_path: Path, args: list[str], needle: str) -> None:
    (tmp_path / "file").write_text("not a folder")
    result = _study(tmp_path, *[a.replace("{tmp}", str(tmp_path)) for a in args])
    assert result.exit_code == 2, result.output + result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and needle in lines[0], lines
    assert not (tmp_path / "store").exists() and not (tmp_path / "out").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["file"]  # no store, VLM cache or output folder anywhere


def test_a_dry_run_reads_a_missing_store_without_creating_it(tmp_path: Path) -> None:
    result = _study(tmp_path, "--dry-run")
    assert result.exit_code == 0, result.output + result.stderr
    assert "cost estimate: 14 run(s) to train (0 already FINISHED)" in result.output
    text = " ".join(result.output.split())
    assert "simulated on censored steps" in text and "a DNF at the budget" in text  # not a t-approximation
    assert "seeds per arm" in text
    assert not any(tmp_path.iterdir())  # a read-only step: no store, no folder, no cache, no output


def test_the_taxonomy_sweep_defaults_to_the_taxonomy_commands(tmp_path: Path) -> None:
    from vlmrl_cli.probe.scoring import DEFAULT_STATES

    help_text = " ".join(runner.invoke(app, ["study", "--help"]).output.split())
    assert f"(default {DEFAULT_STATES})" in help_text
    result = runner.invoke(app, ["study", "--regime", "norm=smoke", "--arms", "hybrid", "--seeds", "1",
                                 "--profiles", "default", "--dry-run", "--tracking-uri", _uri(tmp_path),
                                 "--out", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    assert f"taxonomy: {DEFAULT_STATES} sweep positions" in " ".join(result.output.split())


def test_every_study_option_is_a_config_field_a_run_option_or_a_documented_cli_one() -> None:
    """The study's own options come from ``StudySettings``' fields; a new option must be a new field
    (or a run's option, or say why it is neither in ``CLI_ONLY``)."""
    import dataclasses

    import typer

    from vlmrl_cli.cli import options as opt
    from vlmrl_cli.cli import study as cmd
    from vlmrl_cli.core.fields import help_of
    from vlmrl_cli.study.settings import StudySettings
    from vlmrl_cli.training.config import RunConfig

    command = typer.main.get_command(app).commands["study"]  # type: ignore[attr-defined]
    options = {p.name: p for p in command.params}
    fields = {f.name: f for f in dataclasses.fields(StudySettings)}
    vlm = {o.name for o in opt.VLM_OPTIONS}
    own = {o.name for o in cmd.SETTING_OPTIONS}
    assert own == {f"study_{name}" for name in fields}
    assert set(options) == own | set(cmd.RUN_OPTIONS) | vlm | set(cmd.CLI_ONLY)
    assert not own & (set(cmd.RUN_OPTIONS) | vlm | set(cmd.CLI_ONLY))
    # each study option is its field's: the field's flag and help
    for name, f in fields.items():
        flag = f.metadata.get("flag", "--" + name.replace("_", "-"))
        assert options[f"study_{name}"].opts == [flag], name
        assert options[f"study_{name}"].help == help_of(f) and help_of(f), name
    # each run option sets a key of the runs' own config
    run_fields = {f.name for f in dataclasses.fields(RunConfig)}
    keys = opt._RUN_KEYS | {"seeds": "seeds", "seed_list": "seeds"}
    assert {keys[name].split(".")[0] for name in cmd.RUN_OPTIONS} <= run_fields
