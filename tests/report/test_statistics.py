"""The report's statistics end to end: score intervals, attribution rows, hovering, independent streams."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from tests.report.fake_mlflow import ALL_SUCCEED, WINDOW, build_fake_experiment
from vlmrl_cli import paper
from vlmrl_cli.analysis.stats import Streams
from vlmrl_cli.report.claims import INCONCLUSIVE
from vlmrl_cli.report.table2 import build_table2
from vlmrl_cli.report.writer import ReportConfig, write_report
from vlmrl_cli.tasks.registry import get_task

REPORTED = json.loads(paper.REPORTED.read_text())


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    root = tmp_path_factory.mktemp("stats")
    uri = f"sqlite:///{root / 'mlflow.db'}"
    build_fake_experiment(uri, "ALL", arms=("hybrid", "baseline", "kinematic"), runs=ALL_SUCCEED)
    cfg = ReportConfig(experiment="ALL", tracking_uri=uri, out=root / "rep", window=WINDOW, n_boot=100,
                       log_to_mlflow=False)
    return write_report(cfg, get_task)


def _claim(result, cid: str):
    return next(c for c in result.claims if c.id == cid)


def test_five_of_five_vs_five_of_five_is_inconclusive_with_a_wide_interval(report) -> None:
    gap = _claim(report, "reliability_gap")
    assert gap.estimate.value == 0.0
    assert gap.estimate.low < -0.4 and gap.estimate.high > 0.4  # Newcombe, not a bootstrap [0, 0]
    assert gap.verdict == INCONCLUSIVE and gap.p_value == 1.0
    for cid in ("detached_success_hybrid", "reliability_hybrid"):
        assert _claim(report, cid).estimate.low == pytest.approx(0.5655, abs=1e-3)  # Wilson 5/5


def test_claims_crediting_the_vlm_are_judged_on_hybrid_vs_kinematic(report) -> None:
    for cid in ("vlm_speedup_-130", "vlm_reliability", "vlm_distilled"):
        c = _claim(report, cid)
        assert c.arms == "hybrid vs kinematic" and "judged on hybrid vs kinematic" in c.reason
        assert c.estimate.has_ci and np.isfinite(c.p_value)
    assert _claim(report, "vlm_distilled").verdict == INCONCLUSIVE  # 5/5 vs 5/5 again
    claims_md = (report.out / "claims.md").read_text()
    assert "hybrid vs kinematic" in claims_md and "Newcombe" in claims_md


def test_attribution_table_has_every_pair_with_intervals_and_p_values(report) -> None:
    att = pd.read_csv(report.out / "attribution.csv")
    assert set(att["pair"]) == {"hybrid vs baseline", "hybrid vs kinematic", "kinematic vs baseline"}
    speed = att[(att["pair"] == "hybrid vs kinematic") & (att["metric"] == "speedup_-130")].iloc[0]
    assert speed["value"] > 1 and speed["ci_low"] <= speed["value"] <= speed["ci_high"]
    # hybrid finishes every threshold before every kinematic seed: exact p of a full 5 vs 5 separation
    assert speed["p_value"] == pytest.approx(2 / 252)
    rel = att[(att["pair"] == "kinematic vs baseline") & (att["metric"] == "reliability_diff")].iloc[0]
    assert rel["ci_low"] < -0.4 and rel["ci_high"] > 0.4 and rel["p_value"] == 1.0
    assert att["vlm"].str.contains("SIMULATED VLM").all()
    md = (report.out / "report.md").read_text()
    assert "what the VLM itself adds" in md and "Verdict rule" in md


def test_hovering_arm_is_flagged_in_the_report(report) -> None:
    hack = pd.read_csv(report.out / "hacking.csv").set_index("arm")
    assert hack.loc["kinematic", "flagged_seeds"] == 5 and hack.loc["hybrid", "flagged_seeds"] == 0
    assert hack.loc["kinematic", "flagged_ci_low"] > 0.5
    assert hack.loc["hybrid", "eval_episodes"] == 25
    for name in ("hacking.png", "performance_profile.png", "hacking.md"):
        assert (report.out / name).stat().st_size > 0
    assert "SIMULATED VLM" in (report.out / "hacking.md").read_text()


def test_full_window_rows_sit_beside_the_partial_window_ones(report) -> None:
    long = pd.read_csv(report.out / "table2.csv").set_index(["metric", "arm"])
    partial, full = long.loc[("steps_-190", "hybrid"), "value"], long.loc[("full_steps_-190", "hybrid"), "value"]
    assert full >= partial  # a full window can only come later


def _per_seed(arms: list[str]) -> pd.DataFrame:
    rows = []
    for i, arm in enumerate(arms):
        for seed in range(4):
            steps = 1000.0 * (10 + 3 * i + seed)
            rows.append({"arm": arm, "seed": seed, "run_id": f"{arm}{seed}", "config_hash": "h", "preset": "p",
                         "budget": 50000, "steps_-190": steps, "steps_-130": steps + 500 * seed,
                         "final_return": -110.0 - seed - i, "episodes": 10, "eval_success_rate": 1.0,
                         "eval_mean_length": 120.0, "eval_mean_return": -120.0})
    return pd.DataFrame(rows)


def test_adding_an_arm_changes_no_other_interval() -> None:
    empty = pd.DataFrame(columns=["run_id", "arm", "seed", "episode", "length"])

    def build(arms: list[str]) -> pd.DataFrame:
        t = build_table2(_per_seed(arms), empty, REPORTED, (-190.0, -130.0), Streams(7), window=10, n_boot=200)
        return pd.concat([t.cells, t.speedups]).set_index(["metric", "arm"])

    small, big = build(["hybrid", "baseline"]), build(["hybrid", "baseline", "kinematic"])
    common = small.index
    pd.testing.assert_frame_equal(small.loc[common, ["value", "ci_low", "ci_high"]],
                                  big.loc[common, ["value", "ci_low", "ci_high"]])
