"""The cross-task primary family: Holm across every task's primary comparisons, re-judged."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from vlmrl_cli.analysis.multiplicity import adjust
from vlmrl_cli.study.cross_task import PRIMARY, primary_family, to_markdown


def _map(p_base: float, p_kin: float) -> pd.DataFrame:
    row: dict[str, object] = {}
    for key, p in zip(PRIMARY, (p_base, p_kin), strict=True):
        row |= {f"{key}.speedup": 1.3, f"{key}.low": 1.1, f"{key}.high": 1.5, f"{key}.p": p,
                f"{key}.p_adj": min(1.0, 6 * p), f"{key}.tost_low": 1.15, f"{key}.tost_high": 1.45,
                f"{key}.direction": 0.3, f"{key}.equivalence_ok": "True", f"{key}.verdict": "faster",
                f"{key}.test": "Mann-Whitney U on steps, DNF censored (exact p)"}
    return pd.DataFrame([row])


def test_the_family_is_holm_across_every_task_and_rejudges_each_verdict() -> None:
    maps = {"a": _map(0.001, 0.008), "b": _map(0.02, 0.3), "c": _map(0.004, 0.5), "d": _map(0.006, 0.9)}
    df = primary_family(maps)
    raw = [0.001, 0.008, 0.02, 0.3, 0.004, 0.5, 0.006, 0.9]
    assert df["p"].tolist() == raw and len(df) == 8
    assert df["p_family"].to_numpy() == pytest.approx(adjust(raw, "holm"))
    # Holm over 8: 0.001 x 8 = 0.008 rejects; 0.02 x 4 = 0.08 does not: a study's "faster" turns inconclusive
    verdicts = dict(zip(zip(df["task"], df["comparison"], strict=True), df["verdict"], strict=True))
    assert verdicts[("a", "hybrid vs baseline")] == "faster"
    assert verdicts[("b", "hybrid vs baseline")] == "inconclusive, leans faster"
    assert (df["verdict_within_study"] == "faster").all()
    text = to_markdown(df)
    assert "one family of 8 tests" in text and "Holm" in text and "| exact |" in text


def test_a_comparison_not_made_stays_out_of_the_family() -> None:
    maps = {"a": _map(0.01, math.nan), "b": _map(0.01, 0.01)}
    df = primary_family(maps)
    assert np.isnan(df["p_family"].iloc[1]) and df["p_family"].iloc[0] == pytest.approx(0.03)


def test_the_committed_primary_family_is_what_the_committed_studies_give() -> None:
    # results/compare/primary_family.csv is drawn by scripts/cross_task_family.py from the four
    # committed regime maps; redrawing a study without redrawing the family fails here
    from pathlib import Path

    from vlmrl_cli.study.cross_task import TASK_SCALED_STUDIES, family_from_files

    root = Path(__file__).resolve().parents[2]
    drawn = family_from_files({t: root / d for t, d in TASK_SCALED_STUDIES.items()})
    committed = pd.read_csv(root / "results/compare/primary_family.csv")
    assert committed["task"].tolist() == drawn["task"].tolist()
    assert committed["p_family"].to_numpy() == pytest.approx(drawn["p_family"].to_numpy(), rel=1e-9)
    assert committed["verdict"].tolist() == drawn["verdict"].tolist()
