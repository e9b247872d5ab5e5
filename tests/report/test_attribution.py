"""Attribution verdicts: faster, equivalent within the margin (TOST), inconclusive; claims follow them."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from vlmrl_cli import paper
from vlmrl_cli.analysis.stats import Streams
from vlmrl_cli.report.attribution import adjust_family, attribution_markdown, compare_arms, lookup, lookup_verdict
from vlmrl_cli.report.claims import NOT_REPRODUCED, REPRODUCED, evaluate_claims
from vlmrl_cli.report.table2 import build_table2, floor_thresholds

THRESHOLDS = (-190.0, -130.0)
BUDGET = 300_000


def _per_seed(steps: dict[str, list[float]]) -> pd.DataFrame:
    rows = []
    for arm, values in steps.items():
        for seed, s in enumerate(values):
            rows.append({"arm": arm, "seed": seed, "run_id": f"{arm}{seed}", "config_hash": arm, "preset": "p",
                         "budget": BUDGET, "steps_-190": 5000.0, "steps_-130": s, "full_steps_-190": 5000.0,
                         "full_steps_-130": s, "first_window_step": 5000.0, "final_return": -110.0 - seed % 3,
                         "auc": -150.0 + seed % 5, "episodes": 100, "eval_success_rate": 1.0,
                         "eval_mean_length": 120.0, "eval_mean_return": -120.0, "detached_success": 1.0})
    return pd.DataFrame(rows)


def _data() -> pd.DataFrame:
    rng = np.random.default_rng(0)
    base = list(rng.normal(100_000, 5_000, 20))
    same = list(rng.normal(100_000, 5_000, 20))  # the kinematic arm: alike
    fast = [s / 1.6 for s in base]  # the hybrid: 1.6x faster than the baseline
    return _per_seed({"baseline": base, "kinematic": [s / 1.6 for s in same], "hybrid": fast})


def test_verdicts_name_faster_and_equivalence_with_its_margin() -> None:
    per_seed = _data()
    comparisons = compare_arms(per_seed, THRESHOLDS, Streams(0), n_boot=400)
    assert lookup_verdict(comparisons, "hybrid", "baseline", "speedup_-130")[0] == "faster"
    verdict, low, high = lookup_verdict(comparisons, "hybrid", "kinematic", "speedup_-130")
    assert verdict == "equivalent within 1.15x" and 1 / 1.15 < low < high < 1.15
    assert {"verdict", "tost_low", "tost_high"} <= set(comparisons.columns)
    assert "auc_diff" in set(comparisons["metric"])
    md = attribution_markdown(comparisons)
    assert "| Verdict |" in md and "equivalent within 1.15x" in md
    narrow = compare_arms(per_seed, THRESHOLDS, Streams(0), n_boot=400, margin=1.01)
    assert lookup_verdict(narrow, "hybrid", "kinematic", "speedup_-130")[0] == "inconclusive"


def test_a_vlm_claim_is_not_reproduced_when_the_arms_are_equivalent() -> None:
    per_seed = _data()
    reported = json.loads(paper.REPORTED.read_text())
    empty = pd.DataFrame(columns=["run_id", "arm", "seed", "episode", "length"])
    table = build_table2(per_seed, empty, reported, THRESHOLDS, Streams(0), n_boot=400)
    results = {r.id: r for r in evaluate_claims(table, per_seed, reported, Streams(0), n_boot=400)}
    vlm = results["vlm_speedup_-130"]
    assert vlm.verdict == NOT_REPRODUCED and "equivalent within 1.15x" in vlm.reason
    assert results["speedup_-130"].verdict in (REPRODUCED, NOT_REPRODUCED)  # judged on its own CI, not equivalence


def test_a_threshold_every_seed_crosses_at_its_first_window_is_a_floor() -> None:
    assert floor_thresholds(_data(), THRESHOLDS) == [-190.0]


def test_the_speedups_are_one_family_adjusted_side_by_side_with_the_raw_p() -> None:
    per_seed = _data()
    holm = compare_arms(per_seed, THRESHOLDS, Streams(0), n_boot=200)
    raw = compare_arms(per_seed, THRESHOLDS, Streams(0), n_boot=200, adjust="none")
    steps = holm["metric"].str.startswith("speedup_") & np.isfinite(holm["value"])
    assert (holm.loc[steps, "p_adj"] >= holm.loc[steps, "p_value"]).all()
    np.testing.assert_array_equal(raw.loc[steps, "p_adj"], raw.loc[steps, "p_value"])
    assert holm.loc[~steps, "p_adj"].isna().all()  # reliability, area: not in the family
    assert holm.loc[steps, "logrank_p"].notna().all() and (holm.loc[steps, "logrank_p_adj"] >= 0).all()
    md = attribution_markdown(holm, adjust="holm")
    assert "| p | p adjusted (holm) | Log-rank p (holm-adjusted) |" in md


def test_a_speedup_significant_alone_is_judged_on_its_adjusted_p() -> None:
    comparisons = compare_arms(_data(), THRESHOLDS, Streams(0), n_boot=200, adjust="none")
    row = (comparisons["pair"] == "hybrid vs baseline") & (comparisons["metric"] == "speedup_-130")
    # pretend this one came out at p = 0.04 with its interval above 1; the other speedups at p = 0.5
    steps = comparisons["metric"].str.startswith("speedup_") & np.isfinite(comparisons["value"])
    edited = comparisons.assign(p_value=np.where(row, 0.04, np.where(steps, 0.5, comparisons["p_value"])),
                                logrank_p=np.where(row, 0.001, comparisons["logrank_p"]))
    alone, family = adjust_family(edited, "none"), adjust_family(edited, "holm")
    assert lookup_verdict(alone, "hybrid", "baseline", "speedup_-130")[0] == "faster"
    assert lookup_verdict(family, "hybrid", "baseline", "speedup_-130")[0] == "inconclusive, leans faster"
    found = lookup(family, "hybrid", "baseline", "speedup_-130")
    assert found is not None and found[1] == 0.04 and found[2] == 0.04 * int(steps.sum())
    assert family.loc[row, "tests_disagree"].item() == "log-rank only"
