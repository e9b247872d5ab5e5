"""The study's family of comparisons: one adjustment over the map and the controls, the verdicts on
the adjusted p, both tests in the tables."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
import pytest

from vlmrl_cli.study import markdown, outputs, pipeline, verdicts
from vlmrl_cli.study.config import build_study
from vlmrl_cli.study.outputs import StudyResult


def _cmp(key: str, p: float, low: float, high: float, logrank_p: float | None = None, verdict: str = "faster",
         direction: float = 0.4) -> dict[str, Any]:
    """The columns of one comparison as ``_pair_columns`` writes them (judged alone, on the raw p)."""
    return {f"{key}.speedup": (low + high) / 2, f"{key}.low": low, f"{key}.high": high, f"{key}.p": p,
            f"{key}.p_adj": math.nan, f"{key}.logrank_p": p if logrank_p is None else logrank_p,
            f"{key}.logrank_p_adj": math.nan, f"{key}.tests_disagree": "", f"{key}.test": "Mann-Whitney",
            f"{key}.tost_low": low + 0.01, f"{key}.tost_high": high - 0.01, f"{key}.direction": direction,
            f"{key}.equivalence_ok": True, f"{key}.verdict": verdict}


def _rows() -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    regime = {"regime": "paper", "seeds": 20} | _cmp("hybrid_vs_baseline", 4.5e-8, 1.60, 2.01) | _cmp(
        "hybrid_vs_kinematic", 0.51, 0.91, 1.26, verdict="inconclusive") | _cmp(
        "kinematic_vs_baseline", 0.11, 0.77, 0.97, verdict="inconclusive", direction=-0.3)
    regime |= {"hybrid_vs_hybrid-shuffled.speedup": math.nan, "hybrid_vs_hybrid-shuffled.verdict": verdicts.NEITHER}
    sides = {"question": "dose?", "a.n": 20, "b.n": 20, "a.reached": 19, "b.reached": 17, "a.steps": 243_229.0,
             "b.steps": 256_562.0}
    controls = [{"control": "alpha=100 kin=0.5 vs alpha=0"} | sides | _cmp("cmp", 0.04, 1.02, 1.30, logrank_p=1e-4),
                {"control": "alpha=25 kin=2 vs alpha=0"} | sides | _cmp("cmp", 2.9e-5, 1.33, 1.71)]
    return [regime], controls


def test_the_map_and_the_controls_are_one_family() -> None:
    rows, controls = _rows()
    assert verdicts.family_size(rows, controls) == 5  # the pair where neither arm reached is not a test
    new_rows, new_controls = verdicts.adjust_family(rows, controls, "holm")
    assert new_rows[0]["hybrid_vs_baseline.p_adj"] == pytest.approx(5 * 4.5e-8)
    assert new_rows[0]["hybrid_vs_baseline.verdict"] == "faster"
    # faster on its own at p = 0.04; Holm over 5 comparisons: 3 x 0.04 = 0.12
    assert new_controls[0]["cmp.p_adj"] == pytest.approx(0.12)
    assert new_controls[0]["cmp.verdict"] == "inconclusive, leans faster"
    assert new_controls[0]["cmp.tests_disagree"] == "log-rank only"
    # interval [0.77, 0.97] with an adjusted p far above 0.05: inconclusive, leaning slower
    assert new_rows[0]["kinematic_vs_baseline.verdict"] == "inconclusive, leans slower"
    assert new_rows[0]["hybrid_vs_hybrid-shuffled.verdict"] == verdicts.NEITHER
    assert "hybrid_vs_hybrid-shuffled.p_adj" not in new_rows[0]
    assert rows[0]["hybrid_vs_baseline.p_adj"] != rows[0]["hybrid_vs_baseline.p_adj"]  # the inputs are not changed


def test_without_adjustment_the_p_values_and_the_one_rule_stand_alone() -> None:
    rows, controls = _rows()
    _, alone = verdicts.adjust_family(rows, controls, "none")
    assert alone[0]["cmp.p_adj"] == 0.04 and alone[0]["cmp.verdict"] == "faster"
    bh_rows, _ = verdicts.adjust_family(rows, controls, "bh")
    holm_rows, _ = verdicts.adjust_family(rows, controls, "holm")
    assert bh_rows[0]["kinematic_vs_baseline.p_adj"] <= holm_rows[0]["kinematic_vs_baseline.p_adj"]


def test_the_tables_show_raw_and_adjusted_p_and_both_tests() -> None:
    rows, controls = verdicts.adjust_family(*_rows(), "holm")
    text = markdown.format_speedup(controls[0], "cmp")
    assert text.startswith("1.16x [1.02, 1.30], p = 0.04 (adj. 0.12); log-rank p = 0.0001 (adj. 0.0003)")
    assert "**the tests disagree**: only the log-rank rejects" in text
    assert text.endswith("(inconclusive, leans faster)")
    head = markdown.map_markdown(rows, -130.0, adjust="holm").splitlines()[0]
    assert "rank p (holm-adj.); log-rank p (holm-adj.)" in head
    controls_head = markdown.controls_markdown(controls, -130.0, 1.15, adjust="bh").splitlines()[0]
    assert "rank p (bh-adj.)" in controls_head and "not adjusted" in controls_head


def test_the_summary_and_the_method_state_the_family_and_the_adjustment() -> None:
    rows, controls = verdicts.adjust_family(*_rows(), "holm")
    first = markdown.summary(rows, pd.DataFrame(), -130.0, 0.05, "paper", controls, 1.15, "holm")[0]
    assert "one family of 5 tests, adjusted by Holm's step-down" in first
    assert "excludes 1 on the same side" in first
    cfg = build_study([], {"paper": {"preset": "smoke"}}, profiles=(), flickers=(), alphas=(), kin_scales=(),
                      query_flickers=(), adjust="bh")
    result = StudyResult(regime_map=pd.DataFrame(rows), controls=pd.DataFrame(controls))
    md = outputs.to_markdown(cfg, result, pd.DataFrame(columns=["regime"]), True, None)
    method = md[md.index("## Method"):]
    assert "one family of 5 tests, adjusted by Benjamini-Hochberg" in method
    assert "The rank test drives the verdict" in method and "log-rank" in method


def test_a_bad_adjustment_is_refused_when_the_study_is_built() -> None:
    from vlmrl_cli.core.errors import BadInput

    with pytest.raises(BadInput, match="--adjust is one of holm, bh, none"):
        build_study([], {"paper": {"preset": "smoke"}}, profiles=(), flickers=(), alphas=(), kin_scales=(),
                    query_flickers=(), adjust="bonferroni")


def test_an_area_on_a_zero_to_one_return_scale_keeps_its_digits() -> None:
    from vlmrl_cli.study.markdown import format_difference

    small = {"k.auc_diff": -0.0123, "k.auc_low": -0.02, "k.auc_high": -0.004, "k.auc_p": 0.01,
             "k.auc_verdict": "lower"}
    assert format_difference(small, "k", "auc").startswith("-0.012 [-0.020, -0.004]")
    large = {**small, "k.auc_diff": 7.44, "k.auc_low": 2.1, "k.auc_high": 12.5}
    assert format_difference(large, "k", "auc").startswith("+7.4 [+2.1, +12.5]")


def _hacking_seeds(baseline: list[float], hybrid: list[float], pbrs: list[float]) -> pd.DataFrame:
    arms = ["baseline"] * len(baseline) + ["hybrid"] * len(hybrid) + ["hybrid-dense-pbrs"] * len(pbrs)
    return pd.DataFrame({"arm": arms, "eval_success_rate": [*baseline, *hybrid, *pbrs]})


def test_the_potential_form_removes_the_hacking_only_where_the_hybrid_hacks() -> None:
    rng = np.random.default_rng(0)
    good, bad = [1.0] * 8, [0.2, 0.3, 0.1, 0.2, 0.25, 0.15, 0.3, 0.2]
    removed = verdicts.hacking_answer(_hacking_seeds(good, bad, good), rng, n_boot=300)
    assert removed is not None and removed.startswith("**removed**")
    kept = verdicts.hacking_answer(_hacking_seeds(good, bad, bad), rng, n_boot=300)
    assert kept is not None and kept.startswith("**not removed**")
    nothing = verdicts.hacking_answer(_hacking_seeds(good, good, bad), rng, n_boot=300)
    assert nothing is not None and nothing.startswith("**no hacking to remove**")
    assert "fails more often than the hybrid" in nothing
    assert "no seed failed in either arm: no test" in nothing  # baseline and hybrid tie: no p of 1 printed


def test_no_hacking_answer_without_every_arm() -> None:
    seeds = _hacking_seeds([1.0, 1.0], [1.0, 1.0], [])
    assert verdicts.hacking_answer(seeds, np.random.default_rng(0)) is None


def test_a_partial_family_says_the_finished_one_is_larger() -> None:
    row = {"regime": "zoo", "seeds": 10}
    lines = markdown.summary([row], pd.DataFrame(), -130.0, 0.05, "zoo", planned=15)
    assert "the finished study's family holds 15" in lines[0] and "15 not measured yet" in lines[0]
    assert "finished study's family" not in markdown.summary([row], pd.DataFrame(), -130.0, 0.05, "zoo")[0]


def test_a_comparison_without_a_test_is_not_called_unmeasured() -> None:
    rows, controls = _rows()  # one map pair where neither arm reached: measured, but no test
    lines = markdown.summary(rows, pd.DataFrame(), -130.0, 0.05, "paper", controls, planned=6)
    assert verdicts.untestable(rows, controls) == 1
    assert "1 of them have no test" in lines[0]
    assert "not measured yet" not in lines[0]
    assert "not measured yet" in markdown.summary(rows, pd.DataFrame(), -130.0, 0.05, "paper", controls,
                                                   planned=8)[0]


def test_a_dose_point_that_is_the_hybrids_own_regime_is_not_counted_twice() -> None:
    """The dose control at the hybrid's own alpha and kin_scale against alpha 0 is the map's hybrid vs
    kinematic on the same runs: it is listed once (in the map), and the family holds it once."""
    layers = [{"arms": ["baseline", "hybrid", "kinematic", "hybrid-shuffled"], "seeds": [0, 1],
               "shaping": {"alpha": 5.0, "kin_scale": 0.5}}]
    cfg = build_study(layers, {"paper": {"preset": "smoke"}}, profiles=(), flickers=(), alphas=(5.0, 10.0),
                      kin_scales=(0.5,), query_flickers=())
    every = [c.name for c in verdicts.controls(cfg.cells)]
    kept = [c.name for c in verdicts.controls(cfg.cells, cfg.regimes)]
    assert kept == ["alpha=10 kin=0.5 vs alpha=0", "alpha=10 kin=0.5 vs its placebo"] and len(every) == 3
    assert verdicts.twin_lines(cfg.cells, cfg.regimes) == [
        "- Control `alpha=5 kin=0.5 vs alpha=0` is the map's `paper: hybrid vs kinematic` (the same runs): listed and "
        "counted there, once."]
    assert pipeline.planned_family(cfg) == 4 + 2  # 4 map pairs in one regime, 2 controls
