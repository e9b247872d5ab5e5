"""One arm registry: an arm added to a copy of ``ARMS`` reaches Table 2, the attribution table, the
report's files, the study's regime map and ``vlmrl run --dry-run`` with no other edit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from tests.report.fake_mlflow import WINDOW, FakeRun, build_fake_experiment
from vlmrl_cli.analysis.load import load_experiment
from vlmrl_cli.analysis.stats import Streams
from vlmrl_cli.report.attribution import attribution_markdown, compare_arms, registry_pairs
from vlmrl_cli.report.markdown import table2_markdown
from vlmrl_cli.report.table2 import build_table2, order_arms
from vlmrl_cli.report.writer import ReportConfig, ReportResult, write_report
from vlmrl_cli.shaping import arms as arms_mod
from vlmrl_cli.shaping.arms import ARMS, ArmSpec, Comparison, PotentialSource
from vlmrl_cli.study import markdown, verdicts
from vlmrl_cli.tasks.registry import get_task
from vlmrl_cli.tracking import store

HALF = ArmSpec("hybrid-half", "the hybrid at half the potential (a test arm)", True, PotentialSource.MCQ,
               compared_with=(Comparison("hybrid", "half the potential"),), report_order=1)
REGISTRY = {**ARMS, HALF.name: HALF}
THRESHOLDS = (-190.0, -130.0)


def _per_seed(steps: dict[str, list[float]]) -> pd.DataFrame:
    rows = [{"arm": arm, "seed": seed, "run_id": f"{arm}{seed}", "config_hash": arm, "preset": "p",
             "budget": 300_000, "steps_-190": 5000.0, "steps_-130": s, "full_steps_-190": 5000.0,
             "full_steps_-130": s, "first_window_step": 5000.0, "final_return": -110.0 - seed % 3,
             "auc": -150.0 + seed % 5, "episodes": 100, "eval_success_rate": 1.0, "eval_mean_length": 120.0,
             "eval_mean_return": -120.0, "detached_success": 1.0}
            for arm, values in steps.items() for seed, s in enumerate(values)]
    return pd.DataFrame(rows)


def _data() -> pd.DataFrame:
    base = list(np.random.default_rng(0).normal(100_000, 5_000, 8))
    return _per_seed({"baseline": base, "hybrid": [s / 1.6 for s in base], "hybrid-half": [s / 1.3 for s in base]})


def test_the_registry_copy_places_the_new_arm_and_its_pair_and_the_module_registry_is_untouched() -> None:
    assert order_arms(["hybrid-half", "kinematic", "baseline", "hybrid"], REGISTRY) == [
        "hybrid", "baseline", "hybrid-half", "kinematic"]  # order 1 ties baseline: registry order breaks it
    pairs = registry_pairs(REGISTRY)  # in the report's order: the new arm's after hybrid's, before kinematic's
    assert [p.name for p in pairs][3:5] == ["hybrid-half vs hybrid", "kinematic vs baseline"]
    assert tuple(p for p in pairs if p.a != "hybrid-half") == registry_pairs()
    assert "hybrid-half" not in ARMS


def test_the_new_arm_and_its_pair_appear_in_table2_and_the_attribution_table() -> None:
    per_seed, empty = _data(), pd.DataFrame(columns=["run_id", "arm", "seed", "episode", "length"])
    table = build_table2(per_seed, empty, {}, THRESHOLDS, Streams(0), n_boot=100, registry=REGISTRY)
    assert table.arms == ("hybrid", "baseline", "hybrid-half")
    assert "hybrid-half (ours" in table2_markdown(table)
    comparisons = compare_arms(per_seed, THRESHOLDS, Streams(0), n_boot=100, registry=REGISTRY)
    assert list(dict.fromkeys(comparisons["pair"])) == ["hybrid vs baseline", "hybrid-half vs hybrid"]
    assert "| hybrid-half vs hybrid | half the potential |" in attribution_markdown(comparisons)
    # without the registry copy the arm is still shown (after the known ones) but compared with nothing
    plain = compare_arms(per_seed, THRESHOLDS, Streams(0), n_boot=100)
    assert set(plain["pair"]) == {"hybrid vs baseline"}


FAKE_ARMS = ("hybrid", "baseline", "hybrid-half")


@pytest.fixture(scope="module")
def fake_uri(tmp_path_factory: pytest.TempPathFactory) -> str:
    uri = f"sqlite:///{tmp_path_factory.mktemp('registry') / 'mlflow.db'}"
    runs = [FakeRun(arm, s, 20 + 2 * s + shift, -100.0, 1.0, 120.0 + s, per_episode_eval=True)
            for arm, shift in zip(FAKE_ARMS, (0, 20, 8), strict=True) for s in range(3)]
    build_fake_experiment(uri, "HALF", arms=FAKE_ARMS, runs=runs)
    return uri


@pytest.fixture(scope="module")
def report(fake_uri: str, tmp_path_factory: pytest.TempPathFactory) -> ReportResult:
    cfg = ReportConfig(experiment="HALF", tracking_uri=fake_uri, out=tmp_path_factory.mktemp("rep"), window=WINDOW,
                       n_boot=50, log_to_mlflow=False)
    return write_report(cfg, get_task, registry=REGISTRY)


def test_the_report_s_files_show_the_new_arm_and_its_pair(report: ReportResult) -> None:
    out = report.out
    table2 = (out / "table2.md").read_text()
    assert table2.index("hybrid (ours") < table2.index("baseline (ours") < table2.index("hybrid-half (ours")
    attribution = (out / "attribution.md").read_text()
    assert "| hybrid-half vs hybrid | half the potential |" in attribution
    assert "hybrid-half vs hybrid" in (out / "report.md").read_text()


def test_the_study_map_compares_the_new_arm_when_its_comparison_is_in_the_study(fake_uri: str) -> None:
    data = load_experiment(store.connect_existing(fake_uri), "HALF")
    row, _ = verdicts.regime_row("r", data, THRESHOLDS, Streams(0), n_boot=50, window=WINDOW, registry=REGISTRY)
    assert "hybrid-half_vs_hybrid.speedup" in row and "hybrid_vs_baseline.speedup" in row
    head = markdown.map_markdown([row], -130.0, registry=REGISTRY).splitlines()[0]
    assert "Speedup hybrid-half / hybrid" in head and "hybrid-half: reliability" in head
    out_of_study = {**ARMS, HALF.name: ArmSpec(
        HALF.name, HALF.description, True, PotentialSource.MCQ,
        compared_with=(Comparison("hybrid", "half the potential", in_study=False),))}
    row, _ = verdicts.regime_row("r", data, THRESHOLDS, Streams(0), n_boot=50, window=WINDOW,
                                 registry=out_of_study)
    assert "hybrid-half_vs_hybrid.speedup" not in row


def test_vlmrl_run_dry_run_accepts_an_arm_added_to_the_registry(tmp_path: Path,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    from vlmrl_cli.cli.app import app

    # RunConfig validates arms against the module registry: the one place a test must patch it
    monkeypatch.setitem(arms_mod.ARMS, HALF.name, HALF)
    result = CliRunner().invoke(app, ["run", "--preset", "smoke", "--arms", "hybrid-half,baseline", "--seeds", "1",
                                      "--tracking-uri", f"sqlite:///{tmp_path / 'none.db'}", "--dry-run"])
    assert result.exit_code == 0, result.output
    assert "# hybrid-half" in result.output and "0 FINISHED, 2 pending" in result.output
    assert not (tmp_path / "none.db").exists()
