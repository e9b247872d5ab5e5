"""`vlmrl report` end to end on a fake experiment in a temporary sqlite MLflow store."""

from __future__ import annotations

import functools
import os
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from tests.report.fake_mlflow import BUDGET, EXPECTED, WINDOW, build_fake_experiment
from vlmrl_cli.cli.app import app
from vlmrl_cli.report import writer

runner = CliRunner()


@pytest.fixture(autouse=True)
def few_resamples(monkeypatch):
    monkeypatch.setattr(writer, "ReportConfig", functools.partial(writer.ReportConfig, n_boot=100))


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> tuple[str, dict[str, str]]:
    root = tmp_path_factory.mktemp("mlflow")
    uri = f"sqlite:///{root / 'mlflow.db'}"
    kept = build_fake_experiment(uri, "E")
    build_fake_experiment(uri, "ONLY_HYBRID", arms=("hybrid",))
    from mlflow.tracking import MlflowClient

    MlflowClient(tracking_uri=uri).create_experiment("EMPTY")
    return uri, kept


def _report(uri: str, experiment: str, out: Path):
    return runner.invoke(app, ["report", "--experiment", experiment, "--tracking-uri", uri, "--out", str(out),
                               "--window", str(WINDOW), "--thresholds", "-190,-160,-130"])


def _mean(xs: list[int | None]) -> float:
    """The paper's convention: the mean over the seeds that finished."""
    done = [x for x in xs if x is not None]
    return sum(done) / len(done)


def _restricted(xs: list[int | None]) -> float:
    """The one DNF rule: every seed, a DNF at the budget."""
    return sum(BUDGET if x is None else x for x in xs) / len(xs)


def test_report_writes_every_file_with_hand_computed_values(store, tmp_path):
    uri, kept = store
    out = tmp_path / "rep"
    res = _report(uri, "E", out)
    assert res.exit_code == 0, res.output
    for name in ["table2.md", "table2.csv", "table2.tex", "report.md", "claims.md", "claims.csv", "per_seed.csv",
                 *[f"figure{i}.{ext}" for i in (2, 3, 4) for ext in ("png", "pdf")]]:
        assert (out / name).stat().st_size > 0, name

    per_seed = pd.read_csv(out / "per_seed.csv")
    assert set(per_seed["run_id"]) == set(kept.values())  # stale duplicate and FAILED run ignored
    for arm, by_t in EXPECTED.items():
        d = per_seed[per_seed["arm"] == arm].sort_values("seed")
        for t, steps in by_t.items():
            got = [None if pd.isna(v) else int(v) for v in d[f"steps_{t}"]]
            assert got == steps, (arm, t)

    long = pd.read_csv(out / "table2.csv")
    cell = long.set_index(["metric", "arm"])
    for arm, by_t in EXPECTED.items():
        for t, steps in by_t.items():
            assert cell.loc[(f"steps_{t}", arm), "value"] == pytest.approx(_restricted(steps))
            assert cell.loc[(f"finishers_steps_{t}", arm), "value"] == pytest.approx(_mean(steps))
    assert cell.loc[("steps_-130", "baseline"), "n_reached"] == 2
    assert cell.loc[("reliability", "hybrid"), "value"] == 1.0
    assert cell.loc[("reliability", "baseline"), "value"] == pytest.approx(2 / 3)
    assert cell.loc[("eval_length", "hybrid"), "value"] == pytest.approx(125.0)
    base, hyb = EXPECTED["baseline"], EXPECTED["hybrid"]
    assert cell.loc[("speedup_-130", "hybrid"), "value"] == pytest.approx(_restricted(base[-130]) /
                                                                           _restricted(hyb[-130]))
    assert cell.loc[("speedup_-190", "hybrid"), "value"] == pytest.approx((113000 / 3) / 27000)

    md = (out / "table2.md").read_text()
    assert "39,000" in md and "49,000" in md and "(DNF 1/3)" in md
    assert f"{_restricted(base[-130]) / _restricted(hyb[-130]):.2f}x" in md
    assert "200,379" in md and "272,448" in md  # the paper's values beside ours
    report = (out / "report.md").read_text()
    assert "SIMULATED VLM" in report and "Verdict rule" in report and kept["hybrid-0"] in report
    assert "cfg-hybrid" in report
    assert str(out) in res.output.replace("\n", "")


def test_report_logs_one_report_run_in_its_own_experiment_however_often_it_runs(store, tmp_path):
    uri, _ = store
    assert _report(uri, "E", tmp_path / "rep").exit_code == 0
    assert _report(uri, "E", tmp_path / "rep").exit_code == 0
    from mlflow.tracking import MlflowClient

    client = MlflowClient(tracking_uri=uri)
    exp, reports = client.get_experiment_by_name("E"), client.get_experiment_by_name("E-reports")
    assert exp is not None and reports is not None
    assert not client.search_runs([exp.experiment_id], "tags.`vlmrl.kind` = 'report'")  # none among training runs
    runs = [r for r in client.search_runs([reports.experiment_id], "tags.`vlmrl.kind` = 'report'")
            if r.info.run_name == f"report of E -> {tmp_path / 'rep'}"]  # other tests report elsewhere
    assert len(runs) == 1 and runs[0].info.status == "FINISHED"
    names = {a.path for a in client.list_artifacts(runs[0].info.run_id, "report")}
    assert "report/table2.md" in names and "report/figure4.pdf" in names


def test_report_without_baseline_says_speedups_need_it(store, tmp_path):
    uri, _ = store
    out = tmp_path / "one"
    res = _report(uri, "ONLY_HYBRID", out)
    assert res.exit_code == 0, res.output
    assert "needs baseline" in (out / "table2.md").read_text()
    assert "Speedups need the `baseline` arm" in (out / "report.md").read_text()
    assert (out / "figure4.png").exists()


@pytest.mark.parametrize("experiment", ["NOPE", "EMPTY"])
def test_missing_or_empty_experiment_exits_2_with_one_line(store, tmp_path, experiment):
    uri, _ = store
    res = _report(uri, experiment, tmp_path / "x")
    assert res.exit_code == 2
    err = res.stderr.strip()
    assert err.startswith("error:") and len(err.splitlines()) == 1 and experiment in err


def test_a_missing_tracking_database_exits_2_and_creates_nothing(tmp_path):
    res = _report("sqlite:///" + str(tmp_path / "none" / "mlflow.db"), "E", tmp_path / "rep")
    assert res.exit_code == 2 and len(res.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "none").exists() and not (tmp_path / "rep").exists()


def test_a_failed_report_leaves_no_output_folder(store, tmp_path):
    uri, _ = store
    res = _report(uri, "NOPE", tmp_path / "deep" / "rep")
    assert res.exit_code == 2 and not (tmp_path / "deep").exists()


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="needs a non-root POSIX user")
def test_unwritable_out_exits_2_before_reading_mlflow(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        res = _report("sqlite:///" + str(tmp_path / "never" / "mlflow.db"), "E", locked / "rep")
    finally:
        locked.chmod(0o700)
    assert res.exit_code == 2
    assert "output folder" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "never").exists()  # failed before touching the tracking store


def test_out_under_a_file_exits_2_before_reading_mlflow(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    res = _report("sqlite:///" + str(tmp_path / "never" / "m.db"), "E", f / "rep")
    assert res.exit_code == 2 and "output folder" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and not (tmp_path / "never").exists()


def test_bad_thresholds_exit_2(tmp_path):
    res = runner.invoke(app, ["report", "--thresholds", "a,b", "--out", str(tmp_path)])
    assert res.exit_code == 2 and "--thresholds" in res.stderr


def test_every_table_names_the_simulated_vlm(store, tmp_path):
    uri, _ = store
    out = tmp_path / "rep"
    assert _report(uri, "E", out).exit_code == 0
    for name in ("table2.md", "table2.tex", "claims.md", "report.md"):
        assert "SIMULATED VLM" in (out / name).read_text(), name
    for name in ("table2.csv", "claims.csv", "per_seed.csv"):
        assert pd.read_csv(out / name)["vlm"].astype(str).str.contains("SIMULATED VLM").any(), name


@pytest.mark.parametrize(("args", "needle"), [
    (["--experiment", ""], "an experiment needs a name"),
    (["--experiment", "E "], "starts or ends with a space"),
    (["--tracking-uri", " "], "the tracking URI is empty"),
    (["--margin", "1"], "equivalence margin"),
    (["--adjust", "bonferroni"], "--adjust is one of holm, bh, none"),
])
def test_bad_names_and_margins_exit_2_before_anything_exists(tmp_path, args, needle):
    res = runner.invoke(app, ["report", "--tracking-uri", f"sqlite:///{tmp_path / 's' / 'm.db'}",
                              "--out", str(tmp_path / "rep"), *args])
    assert res.exit_code == 2, res.output + res.stderr
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and needle in lines[0], lines
    assert not any(tmp_path.iterdir())


def test_the_console_summary_reads_at_80_columns_in_a_pipe_even_when_every_seed_is_dnf(tmp_path):
    from tests.report.fake_mlflow import FakeRun

    uri = f"sqlite:///{tmp_path / 'm.db'}"
    build_fake_experiment(uri, "DNF", runs=[FakeRun(a, s, 79, -190.0, 0.0, 200.0) for a in ("hybrid", "baseline")
                                             for s in range(3)])
    res = _report(uri, "DNF", tmp_path / "rep")
    assert res.exit_code == 0, res.output + res.stderr
    lines = res.output.splitlines()
    assert max(len(line) for line in lines if not line.startswith(("Report written", "Logged as"))) <= 80
    assert "neither arm reached the threshold" in res.output and "1.00x" not in res.output
    assert "Warning" not in res.stderr and "warn(" not in res.stderr


def _export_of(records: list[dict], path: Path) -> Path:  # type: ignore[type-arg]
    from vlmrl_cli.tracking.transfer import FORMAT, write_records

    write_records(path, [{**r, "format": FORMAT} for r in records])
    return path


@pytest.mark.slow  # imports runs into a store
def test_runs_of_two_numeric_paths_are_refused_unless_allowed(tmp_path: Path) -> None:
    """Committed Acrobot runs trained before the pin, two of them re-tagged as if trained on it."""
    from vlmrl_cli.tracking.transfer import read_records

    source = Path(__file__).resolve().parents[2] / "results" / "tasks" / "acrobot" / "runs-study.jsonl.gz"
    records = [r for r in read_records(source) if r["tags"].get("vlmrl.arm") in ("baseline", "hybrid")
               and r["tags"].get("vlmrl.seed") in ("0", "1")]
    for r in records:
        r["tags"].pop("vlmrl.pin", None)
    for r in records[:2]:
        r["tags"] |= {"vlmrl.pin": "x86-64-v3/1", "vlmrl.pin.env": "MKL_CBWR=COMPATIBLE", "vlmrl.cpu.torch": "AVX2"}
    uri = f"sqlite:///{tmp_path / 'm.db'}"
    result = runner.invoke(app, ["import", str(_export_of(records, tmp_path / "mixed.jsonl.gz")),
                                 "--experiment", "mixed", "--tracking-uri", uri])
    assert result.exit_code == 0, result.output
    out = tmp_path / "report"
    refused = runner.invoke(app, ["report", "--experiment", "mixed", "--tracking-uri", uri, "--out", str(out)])
    lines = [line for line in refused.stderr.splitlines() if line.strip()]
    assert refused.exit_code == 2 and len(lines) == 1 and "2 numeric paths" in lines[0], refused.stderr
    assert "--allow-mixed-paths" in lines[0] and not out.exists()
    allowed = runner.invoke(app, ["report", "--experiment", "mixed", "--tracking-uri", uri, "--out", str(out),
                                  "--allow-mixed-paths"])
    assert allowed.exit_code == 0, allowed.output + allowed.stderr
    assert "numeric paths" in allowed.output and (out / "report.md").exists()
