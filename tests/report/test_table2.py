from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from vlmrl_cli import paper
from vlmrl_cli.report.markdown import format_cell, table2_latex, table2_long, table2_markdown
from vlmrl_cli.report.table2 import NEEDS_BASELINE, build_table2, compare_steps

REPORTED = json.loads(paper.REPORTED.read_text())
THRESHOLDS = (-190.0, -160.0, -130.0)


def _per_seed(arms: dict[str, list[list[float]]]) -> pd.DataFrame:
    rows = []
    for arm, seeds in arms.items():
        for seed, steps in enumerate(seeds):
            rows.append({"arm": arm, "seed": seed, "run_id": f"{arm}{seed}", "config_hash": "h", "preset": "p",
                         "budget": 1000, **{f"steps_{t:g}": s for t, s in zip(THRESHOLDS, steps, strict=True)},
                         "final_return": -100.0 - seed, "episodes": 10, "eval_success_rate": 1.0,
                         "eval_mean_length": 120.0 + seed, "eval_mean_return": -120.0})
    return pd.DataFrame(rows)


def _build(per_seed: pd.DataFrame):
    empty = pd.DataFrame(columns=["run_id", "arm", "seed", "episode", "length"])
    return build_table2(per_seed, empty, REPORTED, THRESHOLDS, np.random.default_rng(0), window=10, n_boot=50)


def test_reported_json_holds_the_papers_table2():
    rows = {r["threshold"]: r for r in REPORTED["table2"]["steps_to_threshold"]}
    assert rows[-130]["hybrid"] == 200379 and rows[-130]["baseline"] == 272448 and rows[-130]["speedup"] == 1.4
    assert rows[-190]["baseline"] == 196717 and rows[-160]["baseline"] == 219679
    assert REPORTED["table2"]["final_reliability"]["baseline"] == 0.6
    assert REPORTED["table1"]["rows"][1]["b"] == "Box [450, 210, 480, 230]"


def test_without_baseline_speedups_say_so():
    t = _build(_per_seed({"hybrid": [[100, 200, 300], [110, 210, np.nan]]}))
    assert not t.has_baseline
    md = table2_markdown(t)
    assert NEEDS_BASELINE in md and "272,448" in md  # the paper's baseline still shown
    assert "(DNF 1/2)" in md
    assert "\\toprule" in table2_latex(t)


def test_all_dnf_cell_and_long_form():
    t = _build(_per_seed({"hybrid": [[100, 200, 300]] * 3, "baseline": [[150, np.nan, np.nan]] * 3}))
    assert format_cell(t.cell("steps_-130", "baseline")) == "DNF 3/3"
    long = table2_long(t).set_index(["metric", "arm"])
    assert long.loc[("speedup_-190", "hybrid"), "value"] == 1.5
    # no baseline seed finished: the restricted means (1000 for a DNF) give a lower bound, 1000 / 300
    assert long.loc[("speedup_-130", "hybrid"), "value"] == pytest.approx(1000 / 300)
    assert long.loc[("finishers_steps_-130", "baseline"), "n_reached"] == 0


def test_markdown_comes_in_narrow_ours_speedup_and_paper_blocks():
    rows = [[100.0, 200.0, 300.0], [120.0, 220.0, 320.0]]
    t = _build(_per_seed({"hybrid": rows, "baseline": rows, "kinematic": rows, "semantic": rows}))
    md = table2_markdown(t)
    assert "*Ours ([95% CI]; steps: restricted means, a DNF counted at the budget)*" in md
    assert "*The paper*" in md and "*Speedup vs baseline" in md
    widest = max(line.count(" | ") + 1 for line in md.splitlines() if line.startswith("| "))
    assert widest <= 5  # the old single table had 11 columns


def test_the_rank_test_of_a_comparison_censors_a_crossing_after_the_budget() -> None:
    # issue 51: a seed whose rolling mean crossed after its budget is a DNF in every test, the rank
    # test included, exactly as if it had never crossed.
    def frame(b_steps: list[float]) -> pd.DataFrame:
        a_steps = [90_000.0, 95_000.0, float("nan"), 99_000.0]
        rows = [{"arm": "kinematic", "seed": i, "budget": 100_000.0, "steps_-100": s} for i, s in enumerate(a_steps)]
        rows += [{"arm": "baseline", "seed": i, "budget": 100_000.0, "steps_-100": s} for i, s in enumerate(b_steps)]
        return pd.DataFrame(rows)

    over = compare_steps(frame([100_240.0, 100_416.0, 101_200.0, 97_000.0]), "kinematic", "baseline", -100.0)[1]
    never = compare_steps(frame([float("nan")] * 3 + [97_000.0]), "kinematic", "baseline", -100.0)[1]
    assert over.n_dnf_b == 3
    assert (over.u, over.p_value) == (never.u, never.p_value)
