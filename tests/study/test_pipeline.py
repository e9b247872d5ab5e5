"""The study's power lines, per comparison from its own reference."""

from __future__ import annotations


def test_power_is_stated_per_comparison_from_its_own_reference_in_restricted_mean_ratios() -> None:
    """Each comparison's power comes from its reference arm's own censored fit: a reference that never
    finished (every seed a DNF) states no speedup power (it once pooled to an sd of 0.010 and "detects
    1.03x"), a reference that finishes says its fit, its observed reliability and a restricted-mean ratio."""
    import math

    import numpy as np
    import pandas as pd

    from vlmrl_cli.study.config import build_study
    from vlmrl_cli.study.pipeline import power_lines

    cfg = build_study([{"seeds": list(range(10)), "arms": ["baseline", "kinematic", "hybrid"]}],
                      {"smoke": {"preset": "smoke"}}, profiles=(), flickers=(), alphas=(), kin_scales=(),
                      query_flickers=())
    budget = float(cfg.base.budget)
    rng = np.random.default_rng(0)
    rows = []
    for arm, finish in (("baseline", 6), ("kinematic", 0), ("hybrid", 10)):
        for seed in range(10):
            steps = float(budget * 0.5 * math.exp(0.3 * rng.standard_normal())) if seed < finish else math.nan
            rows.append({"regime": "smoke", "variant": "", "arm": arm, "seed": seed, "run_id": f"{arm}{seed}",
                         "budget": budget, f"steps_{cfg.top:g}": steps, f"reached_{cfg.top:g}": seed < finish})
    lines = power_lines(cfg, pd.DataFrame(rows))
    assert "family of" in lines[0] and "restricted mean steps" in lines[0]
    by_pair = {line.split(":")[0].lstrip("- "): line for line in lines[1:]}
    assert "observed 6/10" in by_pair["hybrid vs baseline"] and "restricted-mean ratio" in by_pair["hybrid vs baseline"]
    assert "too few finishes" in by_pair["hybrid vs kinematic"]
    assert "Fisher's exact test (alpha 0.05, unadjusted) detects 59% or more against its 0%" in by_pair[
        "hybrid vs kinematic"]
    # issue 51 item 5: each arm's own spread is fitted and named; a finished study's family is the one it adjusted
    assert "(hybrid's 0." in by_pair["hybrid vs baseline"]
    made = power_lines(cfg, pd.DataFrame(rows), made=2)
    assert "alpha 0.05 / 2 " in made[0] and "the comparisons made" in made[0]
