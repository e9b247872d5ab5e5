"""`vlmrl evaluate` end to end on a smoke hybrid run, and SB3's diagnostics in that run; the order of
its output on a stand-in result."""

from __future__ import annotations

import gzip
import json
import pickle
from pathlib import Path
from types import SimpleNamespace

import pytest
from mlflow.tracking import MlflowClient
from PIL import Image
from typer.testing import CliRunner

from vlmrl_cli.cli.app import app

slow = pytest.mark.slow  # the tests of a trained run

runner = CliRunner()


def _uri(root: Path) -> str:
    return f"sqlite:///{root / 'm.db'}"


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """A store holding one finished smoke hybrid run; returns (folder, run id)."""
    root = tmp_path_factory.mktemp("evaluate")
    result = runner.invoke(app, ["run", "--arms", "hybrid", "--seeds", "1", "--preset", "smoke", "--workers", "1",
                                 "--tracking-uri", _uri(root), "--experiment", "e",
                                 "--cache-path", str(root / "cache.sqlite")])
    assert result.exit_code == 0, result.output + result.stderr
    client = MlflowClient(tracking_uri=_uri(root))
    exp = client.get_experiment_by_name("e")
    assert exp is not None
    runs = client.search_runs([exp.experiment_id], filter_string="tags.`vlmrl.kind` = 'train'")
    assert len(runs) == 1
    return root, runs[0].info.run_id


def _evaluate(root: Path, *args: str):  # type: ignore[no-untyped-def]
    return runner.invoke(app, ["evaluate", *args, "--tracking-uri", _uri(root),
                               "--cache-path", str(root / "cache.sqlite")])


@slow
def test_evaluate_writes_a_captioned_gif_and_logs_it_to_the_run(trained: tuple[Path, str]) -> None:
    root, run_id = trained
    out = root / "ev"
    result = _evaluate(root, run_id, "--episodes", "3", "--out", str(out))
    assert result.exit_code == 0, result.output + result.stderr
    assert result.stdout.startswith("WARNING: SIMULATED VLM")
    assert "success rate" in result.output and "mean length" in result.output
    gif = out / "episode-0.gif"
    with Image.open(gif) as im:
        assert getattr(im, "n_frames", 1) > 10
        assert im.size[0] == 300
    assert gif.stat().st_size < 3 * 1024 * 1024
    figures = json.loads((out / "evaluation.json").read_text())
    assert figures["simulated"] is True and "SIMULATED" in figures["note"] and "SIMULATED" in figures["vlm"]
    assert len(figures["returns"]) == 3 and 0.0 <= figures["success_rate"] <= 1.0
    # the GIF replays evaluated episode 0 exactly (same seed, deterministic policy)
    assert figures["gif"]["native_return"] == figures["returns"][0]
    assert figures["gif"]["length"] == figures["lengths"][0]
    assert all("vlm_answer" in f and "phi_raw" in f for f in figures["frames"])
    client = MlflowClient(tracking_uri=_uri(root))
    logged = {a.path for a in client.list_artifacts(run_id, "evaluate")}
    assert logged == {"evaluate/episode-0.gif", "evaluate/evaluation.json"}


@slow
def test_the_smoke_run_has_sb3_training_diagnostics(trained: tuple[Path, str]) -> None:
    root, run_id = trained
    client = MlflowClient(tracking_uri=_uri(root))
    metrics = client.get_run(run_id).data.metrics
    for key in ("train/approx_kl", "train/clip_fraction", "train/entropy_loss", "train/value_loss",
                "train/explained_variance", "train/learning_rate", "rollout/return_100"):
        assert key in metrics, key
    kl = client.get_metric_history(run_id, "train/approx_kl")
    assert len(kl) == 8 and max(m.step for m in kl) == 1024  # smoke: 8 PPO updates of 128 steps
    assert all(-200.0 <= m.value <= 0.0 for m in client.get_metric_history(run_id, "rollout/return_100"))


def _failed_run(root: Path) -> str:
    client = MlflowClient(tracking_uri=_uri(root))
    exp = client.get_experiment_by_name("e")
    assert exp is not None
    run = client.create_run(exp.experiment_id)
    client.set_terminated(run.info.run_id, "FAILED")
    return str(run.info.run_id)


@slow
@pytest.mark.parametrize(("case", "words"), [
    ("unknown", "no run"),
    ("failed", "no model.zip"),
    ("bad-uri", "no tracking database"),
    ("bad-index", "--episode-index"),
])
def test_errors_exit_2_with_one_sentence_and_create_no_folder(
    trained: tuple[Path, str], tmp_path: Path, case: str, words: str
) -> None:
    root, run_id = trained
    out = tmp_path / "ev"
    args = [run_id, "--out", str(out), "--tracking-uri", _uri(root)]
    if case == "unknown":
        args[0] = "0123456789abcdef0123456789abcdef"
    elif case == "failed":
        args[0] = _failed_run(root)
    elif case == "bad-uri":
        args[-1] = f"sqlite:///{tmp_path / 'missing' / 'm.db'}"
    else:
        args += ["--episodes", "2", "--episode-index", "2"]
    result = runner.invoke(app, ["evaluate", *args])
    assert result.exit_code == 2, result.output + result.stderr
    assert result.stderr.startswith("error:") and words in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not out.exists() and not (tmp_path / "missing").exists()


@slow
def test_an_imported_run_evaluates_and_nothing_is_unpickled(trained: tuple[Path, str], tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    root, run_id = trained
    export = tmp_path / "runs.jsonl.gz"
    done = runner.invoke(app, ["export", "--out", str(export), "--models", "--tracking-uri", _uri(root),
                               "--experiment", "e"])
    assert done.exit_code == 0, done.output + done.stderr
    with gzip.open(export, "rt", encoding="utf-8") as f:
        record = json.loads(f.readline())
    assert set(record["binary"]) == {"policy.pth", "vecnormalize.npz"}  # no model.zip, no pickle
    imported = tmp_path / "imported"
    imported.mkdir()
    done = runner.invoke(app, ["import", str(export), "--tracking-uri", _uri(imported), "--experiment", "e"])
    assert done.exit_code == 0, done.output + done.stderr
    client = MlflowClient(tracking_uri=_uri(imported))
    exp = client.get_experiment_by_name("e")
    assert exp is not None
    copy = client.search_runs([exp.experiment_id])[0].info.run_id

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("something was unpickled")

    for name in ("load", "loads", "Unpickler", "_Unpickler"):  # cloudpickle.loads is pickle.loads
        monkeypatch.setattr(pickle, name, refuse)
    evaluated = _evaluate(imported, copy, "--episodes", "3", "--out", str(tmp_path / "ev-copy"))
    original = _evaluate(root, run_id, "--episodes", "3", "--out", str(tmp_path / "ev"))
    assert evaluated.exit_code == 0 and original.exit_code == 0, evaluated.output + evaluated.stderr
    figures = [json.loads((tmp_path / name / "evaluation.json").read_text()) for name in ("ev-copy", "ev")]
    assert figures[0]["returns"] == figures[1]["returns"] and figures[0]["lengths"] == figures[1]["lengths"]


@slow
def test_a_pickled_normaliser_loads_only_when_trusted(trained: tuple[Path, str], tmp_path: Path) -> None:
    root, run_id = trained
    client = MlflowClient(tracking_uri=_uri(root))
    exp = client.get_experiment_by_name("e")
    assert exp is not None
    old = client.create_run(exp.experiment_id, tags={"vlmrl.kind": "train"}).info.run_id
    for name in ("model.zip", "config.json"):
        client.download_artifacts(run_id, name, str(tmp_path))
        client.log_artifact(old, str(tmp_path / name))
    marker = tmp_path / "ran"
    (tmp_path / "vecnormalize.pkl").write_bytes(pickle.dumps(_Payload(marker)))
    client.log_artifact(old, str(tmp_path / "vecnormalize.pkl"))
    client.set_terminated(old)
    refused = _evaluate(root, old, "--episodes", "1", "--out", str(tmp_path / "ev"))
    assert refused.exit_code == 2 and "vecnormalize.pkl, a pickle" in refused.stderr and "--trust-pickle" in \
        refused.stderr
    assert not marker.exists() and not (tmp_path / "ev").exists()
    trusted = _evaluate(root, old, "--episodes", "1", "--out", str(tmp_path / "ev"), "--trust-pickle")
    assert marker.exists() and trusted.exit_code == 2  # trusted, it ran (and is no VecNormalize: refused)


class _Payload:
    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):  # type: ignore[no-untyped-def]
        return (Path.touch, (self.marker,))


@slow
def test_a_parent_run_id_names_its_children_and_arm_seed_pick_one(trained: tuple[Path, str]) -> None:
    root, child = trained
    client = MlflowClient(tracking_uri=_uri(root))
    exp = client.get_experiment_by_name("e")
    assert exp is not None
    (parent,) = client.search_runs([exp.experiment_id], filter_string="tags.`vlmrl.kind` = 'sweep'")
    refused = _evaluate(root, parent.info.run_id)
    assert refused.exit_code == 2 and child in refused.stderr and "--arm ARM --seed N" in refused.stderr
    picked = _evaluate(root, parent.info.run_id, "--arm", "hybrid", "--seed", "0", "--episodes", "1",
                       "--out", str(root / "picked"))
    assert picked.exit_code == 0, picked.output + picked.stderr
    assert child in picked.output
    wrong = _evaluate(root, child, "--arm", "hybrid")
    assert wrong.exit_code == 2 and "drop them" in wrong.stderr


@pytest.mark.parametrize(("uses_vlm", "simulated"), [(True, True), (True, False), (False, True)])
def test_the_simulated_vlm_notice_is_the_first_line_before_any_result(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, uses_vlm: bool, simulated: bool
) -> None:
    # it came after the summary lines: printed on stderr, beside results on stdout, it could land anywhere
    import vlmrl_cli.cli.evaluate as command
    from vlmrl_cli.training import evaluate_trained

    run = SimpleNamespace(name="hybrid-s0", run_id="0123abcd", arm=SimpleNamespace(name="hybrid", uses_vlm=uses_vlm),
                          status="FINISHED", simulated=simulated)
    done = SimpleNamespace(run=run, result=SimpleNamespace(success_rate=0.5, mean_length=150.0, mean_return=-150.0),
                           gif=tmp_path / "episode-0.gif", frames=10, gif_bytes=2048, summary=tmp_path / "e.json")
    monkeypatch.setattr(command, "resolve_child", lambda run_id, *_: run_id)
    monkeypatch.setattr(evaluate_trained, "evaluate_run", lambda cfg, tasks: done)
    result = runner.invoke(app, ["evaluate", "0123abcd", "--episodes", "2"])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()  # stdout and stderr as a terminal shows them
    if uses_vlm and simulated:
        assert lines[0] == command.SIMULATED_NOTICE and result.stdout.splitlines()[0] == command.SIMULATED_NOTICE
        assert lines[1].startswith("run:") and result.output.count("SIMULATED VLM") == 1
    else:
        assert lines[0].startswith("run:") and "SIMULATED" not in result.output
    assert result.stderr == ""


def test_the_default_output_folder_is_under_the_git_ignored_scratch_folder() -> None:
    from vlmrl_cli.training.evaluate_trained import EvaluateConfig

    assert EvaluateConfig(run_id="abc123").out_dir == Path("results/_scratch/evaluate/abc123")
    root = Path(__file__).resolve().parents[2]
    assert "results/_scratch/" in (root / ".gitignore").read_text(encoding="utf-8").splitlines()
    assert EvaluateConfig(run_id="abc123", out=Path("x")).out_dir == Path("x")


@slow
def test_without_out_the_gif_lands_in_the_scratch_folder(trained: tuple[Path, str], tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    root, run_id = trained
    monkeypatch.chdir(tmp_path)  # as if run from a checkout, whose results/ is committed
    result = _evaluate(root, run_id, "--episodes", "1")
    assert result.exit_code == 0, result.output + result.stderr
    assert (tmp_path / "results" / "_scratch" / "evaluate" / run_id / "episode-0.gif").is_file()
    assert [p.name for p in (tmp_path / "results").iterdir()] == ["_scratch"]


def test_a_sweep_without_the_given_arm_and_seed_says_so_instead_of_asking_for_them() -> None:
    # it asked for --arm/--seed, which had been given (issue 50)
    from vlmrl_cli.cli.evaluate import pick_child
    from vlmrl_cli.core.errors import BadInput
    from vlmrl_cli.report.children import ChildRow

    kids = [ChildRow(arm, seed, f"{arm}-{seed}", "FINISHED", 0.0, 1.0) for arm in ("baseline", "hybrid")
            for seed in (0, 1)]
    assert pick_child("p", kids, "hybrid", 1) == "hybrid-1"
    with pytest.raises(BadInput) as unknown:
        pick_child("p", kids, "teleport", 0)
    assert "no training run of arm teleport and seed 0" in str(unknown.value)
    assert "--arm ARM" not in str(unknown.value) and "baseline seed 0 = baseline-0" in str(unknown.value)
    with pytest.raises(BadInput) as no_seed:
        pick_child("p", kids, "hybrid", None)
    assert "pass --seed N, or one of its training runs: hybrid seed 0 = hybrid-0, hybrid seed 1" in str(no_seed.value)
    with pytest.raises(BadInput, match="pass --arm ARM --seed N"):
        pick_child("p", kids, None, None)
    with pytest.raises(BadInput, match="2 training runs of arm hybrid and seed 0"):
        pick_child("p", [*kids, ChildRow("hybrid", 0, "again", "FINISHED", 0.0, 1.0)], "hybrid", 0)
