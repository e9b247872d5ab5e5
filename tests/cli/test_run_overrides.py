"""`vlmrl run --set`, typed validation before anything exists, and `--dry-run`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from mlflow.tracking import MlflowClient
from typer.testing import CliRunner

from vlmrl_cli.cli.app import app

runner = CliRunner()


def _uri(root: Path) -> str:
    return f"sqlite:///{root / 'store' / 'mlflow.db'}"


def _children(root: Path) -> list:  # type: ignore[type-arg]
    client = MlflowClient(tracking_uri=_uri(root))
    exp = client.get_experiment_by_name("vlmrl")
    runs = [] if exp is None else client.search_runs([exp.experiment_id], max_results=1000)
    return [r for r in runs if r.data.tags.get("vlmrl.kind") == "train"]


def _run(root: Path, *args: str):  # type: ignore[no-untyped-def]
    return runner.invoke(
        app, ["run", "--arms", "baseline", "--preset", "smoke", "--workers", "1", "--tracking-uri", _uri(root), *args]
    )


SETS = ("--set", "ppo.n_envs=1", "--set", "ppo.n_steps=128", "--set", "ppo.normalize_reward=false")


@pytest.mark.slow
def test_set_reaches_the_run_params_and_tags_and_changes_the_config_hash(tmp_path: Path) -> None:
    result = _run(
        tmp_path,
        "--seeds",
        "1",
        *SETS,
    )
    assert result.exit_code == 0, result.output + result.stderr
    (run,) = _children(tmp_path)
    params, tags = run.data.params, run.data.tags
    assert params["ppo.n_envs"] == "1" and params["ppo.n_steps"] == "128"
    assert params["ppo.normalize_reward"] == "false" and params["ppo.normalize_obs"] == "true"
    assert tags["vlmrl.preset"] == "smoke"
    assert tags["vlmrl.overrides"] == "ppo.n_envs=1 ppo.n_steps=128 ppo.normalize_reward=false"
    plain = runner.invoke(
        app,
        [
            "run",
            "--arms",
            "baseline",
            "--preset",
            "smoke",
            "--seeds",
            "1",
            "--dry-run",
            "--tracking-uri",
            _uri(tmp_path),
        ],
    )
    assert plain.exit_code == 0
    assert run.data.tags["vlmrl.config_hash"] not in plain.output  # same command without --set: another cell
    assert (
        f"{run.data.tags['vlmrl.config_hash']}  FINISHED"
        in _run(
            tmp_path,
            "--seeds",
            "1",
            "--dry-run",
            *SETS,
        ).output
    )


BAD_SETS = [
    (["--set", "ppo.n_envs=abc"], "ppo.n_envs"),
    (["--set", "ppo.gamma=1.5"], "ppo.gamma"),
    (["--set", "ppo.n_envs=0"], "ppo.n_envs"),
    (["--set", "ppo.learning_rate=-0.001"], "ppo.learning_rate"),
    (["--set", "ppo.batch_size=512"], "ppo.batch_size"),
    (["--set", "shaping.alpha=big"], "shaping.alpha"),
    (["--set", "ppo.nenvs=1"], "did you mean 'ppo.n_envs'"),
    (["--set", "vlm.sim.flicker=2"], "vlm.sim.flicker"),
    (["--set", "ppo.lr_schedule=cosine"], "ppo.lr_schedule"),
    (["--set", "n_envs"], "KEY=VALUE"),
    (["--config", "{file}"], "shaping.alpha"),
    (["--config", "{file}", "--set", "shaping.alpha=3", "--set", "ppo.gamma=1.5"], "ppo.gamma"),
]


@pytest.mark.parametrize(("args", "needle"), BAD_SETS)
def test_each_bad_value_exits_2_naming_the_key_and_creates_nothing(
    tmp_path: Path, args: list[str], needle: str
) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[shaping]\nalpha = "big"\n')
    result = _run(tmp_path, *[a.replace("{file}", str(bad)) for a in args])
    assert result.exit_code == 2, result.output + result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and needle in lines[0], lines
    assert "Traceback" not in result.stderr + result.output
    assert not (tmp_path / "store").exists()  # no store, no folder, so no run


def test_dry_run_prints_toml_that_config_reads_back_to_the_same_jobs(tmp_path: Path) -> None:
    first = runner.invoke(
        app,
        [
            "run",
            "--arms",
            "baseline,hybrid",
            "--seed-list",
            "3,4",
            "--preset",
            "smoke",
            "--set",
            "ppo.n_envs=1",
            "--set",
            "ppo.n_steps=128",
            "--set",
            "shaping.alpha=3",
            "--set",
            "vlm.sim.flicker=0.3",
            "--dry-run",
            "--tracking-uri",
            _uri(tmp_path),
        ],
    )
    assert first.exit_code == 0, first.output + first.stderr
    assert "does not exist (not created)" in first.output and not (tmp_path / "store").exists()
    saved = tmp_path / "dry.toml"
    saved.write_text(first.output)
    again = runner.invoke(app, ["run", "--config", str(saved), "--dry-run"])
    assert again.exit_code == 0, again.output + again.stderr
    assert again.output == first.output
    jobs = [line for line in first.output.splitlines() if line.startswith("# baseline") or line.startswith("# hybrid")]
    assert len(jobs) == 4 and all(line.endswith("pending") for line in jobs)


@pytest.mark.slow
def test_dry_run_tells_finished_from_pending_after_a_partial_sweep(tmp_path: Path) -> None:
    assert _run(tmp_path, "--seed-list", "0").exit_code == 0
    result = _run(tmp_path, "--seed-list", "0,1", "--dry-run")
    assert result.exit_code == 0, result.output + result.stderr
    rows = {line.split()[2]: line.split()[4] for line in result.output.splitlines() if line.startswith("# baseline")}
    assert rows == {"0": "FINISHED", "1": "pending"}
    assert "1 FINISHED, 1 pending" in result.output
    assert len(_children(tmp_path)) == 1  # the dry run trained nothing


def test_sim_profile_flag_and_set_resolve_the_same_knobs(tmp_path: Path) -> None:
    flag = _run(tmp_path, "--arms", "hybrid", "--sim-profile", "llava-table1", "--sim-flicker", "0.3", "--dry-run")
    assert flag.exit_code == 0, flag.output
    assert 'profile = "llava-table1"' in flag.output and "flicker = 0.3" in flag.output
    assert "float_anchor = 0.38" in flag.output
    via_set = _run(tmp_path, "--arms", "hybrid", "--set", "vlm.sim.profile=llava-table1", "--set",
                   "vlm.sim.flicker=0.3", "--dry-run")
    assert via_set.exit_code == 0 and via_set.output == flag.output
    bad = _run(tmp_path, "--sim-profile", "lava", "--dry-run")
    assert bad.exit_code == 2 and "llava-table1" in bad.output + bad.stderr


@pytest.mark.parametrize(("args", "line"), [
    (["--task", "acrobot", "--arms", "baseline,hybrid"],
     "scales: the task's own scales alpha 107, kin_scale 0.152 replace the paper's defaults alpha 5, kin_scale 2"),
    (["--task", "acrobot", "--arms", "kinematic", "--set", "shaping.alpha=5"],
     "scales: the task's own scale kin_scale 0.152 replaces the paper's default kin_scale 2"),
    (["--task", "acrobot", "--arms", "baseline"], None),  # no arm is shaped
    (["--arms", "baseline,hybrid"], None),  # MountainCar's scales are the paper's
])
def test_the_banner_says_when_the_tasks_own_scales_replace_the_defaults(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, args: list[str], line: str | None) -> None:
    from types import SimpleNamespace

    from vlmrl_cli.sweep import preflight
    from vlmrl_cli.sweep import runner as sweep_runner

    monkeypatch.setattr(preflight, "preflight", lambda cfg: None)  # the banner, then a sweep with nothing to do
    monkeypatch.setattr(sweep_runner, "run_sweep",
                        lambda cfg, reporter, checked: SimpleNamespace(elsewhere=[], parent_run_id=None))
    result = runner.invoke(app, ["run", "--preset", "smoke", "--seeds", "1", "--tracking-uri", _uri(tmp_path), *args])
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.split())
    assert "vlmrl run: task" in text
    if line is None:
        assert "scales:" not in text
    else:
        assert line in text


@pytest.mark.parametrize("dry_run", [True, False])
def test_a_runs_config_is_validated_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, dry_run: bool) -> None:
    """Where its layers are merged (``RunConfig.from_sources``); the preflight and the sweep take
    the validated config as it is."""
    from types import SimpleNamespace

    from vlmrl_cli.sweep import runner as sweep_runner
    from vlmrl_cli.training import validation

    validated: list[str] = []
    real = validation.validate_as

    def counting(cls: type, raw: dict[str, Any], **carried: Any) -> Any:
        validated.append(cls.__name__)
        return real(cls, raw, **carried)

    monkeypatch.setattr(validation, "validate_as", counting)
    swept: list[bool] = []

    def run_sweep(cfg: Any, reporter: Any, checked: bool) -> SimpleNamespace:
        swept.append(checked)
        return SimpleNamespace(elsewhere=[], parent_run_id=None)

    monkeypatch.setattr(sweep_runner, "run_sweep", run_sweep)
    args = ["run", "--arms", "hybrid", "--preset", "smoke", "--seeds", "1", "--tracking-uri", _uri(tmp_path)]
    result = runner.invoke(app, [*args, *(["--dry-run"] if dry_run else [])])
    assert result.exit_code == 0, result.output
    assert validated.count("RunConfig") == 1, validated
    assert swept == ([] if dry_run else [True])  # the preflight ran before the sweep, which ran
